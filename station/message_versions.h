// Decoding the bus's messages from untrusted bytes, and the message versions a recorded log
// may hold: a type that grew is read through its earlier layouts (lcmtypes/*_v1_t.lcm and on),
// here beside the messages, so every scan's log stays readable and playable.
#pragma once

#include <cstdint>
#include <exception>

#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_started_t.hpp"
#include "vellum/texture_t.hpp"

namespace vellum::station {

// Decodes an LCM message from untrusted bytes. lcm-gen 1.3.1's decoders throw
// std::length_error for a string whose length field is 0 (found by fuzz_messages); that, like
// any other malformed input, is reported as "does not decode" instead of ending the process.
template <class Msg>
bool SafeDecode(const void* data, int64_t size, Msg* msg) {
  if (size < 0 || size > INT32_MAX) return false;
  try {
    return msg->decode(data, 0, static_cast<int>(size)) >= 0;
  } catch (const std::exception&) {
    return false;
  }
}
// The recorded messages whose type grew (extra lights): a CAPTURE or SCAN_STARTED of
// a log recorded before decodes through its earlier type (capture_v1_t, scan_started_v1_t), as a
// scan without extra lights, so every scan's log stays readable and playable; a SCAN_STARTED
// recorded before the leaf hint (scan_started_v2_t), as a scan without a hint; one recorded before
// the object (scan_started_v3_t), as a scan whose object is auto; one recorded before the live
// view's word on the view's edge (scan_started_v4_t), as a scan the live view saw nothing off.
bool SafeDecode(const void* data, int64_t size, capture_t* msg);
bool SafeDecode(const void* data, int64_t size, scan_started_t* msg);
// Likewise a CALIBRATION recorded before it carried the working volume and the scale error
// (calibration_v1_t): the default working volume, the scale error not measured.
bool SafeDecode(const void* data, int64_t size, calibration_t* msg);
// A PATTERN_SHOWN recorded before it said when the image was handed to the display
// (pattern_shown_v1_t): handed_utime 0, not said.
bool SafeDecode(const void* data, int64_t size, pattern_shown_t* msg);
// A TEXTURE or LIGHT_TEXTURE recorded before it said its samples' bits (texture_v1_t): 8.
bool SafeDecode(const void* data, int64_t size, texture_t* msg);

}  // namespace vellum::station
