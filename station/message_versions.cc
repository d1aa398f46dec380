#include "station/message_versions.h"

#include <algorithm>
#include <utility>

#include "core/geometry/calibration.h"
#include "vellum/calibration_v1_t.hpp"
#include "vellum/capture_v1_t.hpp"
#include "vellum/pattern_shown_v1_t.hpp"
#include "vellum/scan_started_v1_t.hpp"
#include "vellum/scan_started_v2_t.hpp"
#include "vellum/scan_started_v3_t.hpp"
#include "vellum/scan_started_v4_t.hpp"
#include "vellum/texture_v1_t.hpp"

namespace vellum::station {

bool SafeDecode(const void* data, int64_t size, capture_t* msg) {
  if (SafeDecode<capture_t>(data, size, msg)) return true;
  capture_v1_t old;
  if (!SafeDecode<capture_v1_t>(data, size, &old)) return false;
  *msg = capture_t{};
  msg->utime = old.utime;
  msg->seq = old.seq;
  msg->scan_id = old.scan_id;
  msg->station = old.station;
  msg->session = old.session;
  msg->pattern_index = old.pattern_index;
  msg->pattern_count = old.pattern_count;
  msg->projector_width = old.projector_width;
  msg->projector_height = old.projector_height;
  msg->pattern = old.pattern;
  msg->shown_utime = old.shown_utime;
  msg->image = std::move(old.image);
  return true;  // No extra lights.
}

namespace {

// The fields every recorded layout of SCAN_STARTED has, from an earlier one; the rest empty.
template <class Earlier>
scan_started_t StartedFrom(const Earlier& old) {
  scan_started_t msg{};
  msg.utime = old.utime;
  msg.seq = old.seq;
  msg.station = old.station;
  msg.scan_id = old.scan_id;
  msg.session = old.session;
  msg.pattern_count = old.pattern_count;
  msg.projector_width = old.projector_width;
  msg.projector_height = old.projector_height;
  msg.identity = old.identity;
  return msg;
}

}  // namespace

bool SafeDecode(const void* data, int64_t size, scan_started_t* msg) {
  if (SafeDecode<scan_started_t>(data, size, msg)) return true;
  scan_started_v4_t v4;
  if (SafeDecode<scan_started_v4_t>(data, size, &v4)) {
    *msg = StartedFrom(v4);
    msg->light_count = v4.light_count;
    msg->lights = std::move(v4.lights);
    std::copy(v4.leaf_hint, v4.leaf_hint + 4, msg->leaf_hint);
    msg->object = std::move(v4.object);
    return true;  // Nothing seen off the view.
  }
  scan_started_v3_t v3;
  if (SafeDecode<scan_started_v3_t>(data, size, &v3)) {
    *msg = StartedFrom(v3);
    msg->light_count = v3.light_count;
    msg->lights = std::move(v3.lights);
    std::copy(v3.leaf_hint, v3.leaf_hint + 4, msg->leaf_hint);
    return true;  // No object: auto.
  }
  scan_started_v2_t v2;
  if (SafeDecode<scan_started_v2_t>(data, size, &v2)) {
    *msg = StartedFrom(v2);
    msg->light_count = v2.light_count;
    msg->lights = std::move(v2.lights);
    return true;  // No leaf hint.
  }
  scan_started_v1_t v1;
  if (!SafeDecode<scan_started_v1_t>(data, size, &v1)) return false;
  *msg = StartedFrom(v1);
  return true;  // No extra lights, no leaf hint.
}

bool SafeDecode(const void* data, int64_t size, calibration_t* msg) {
  if (SafeDecode<calibration_t>(data, size, msg)) return true;
  calibration_v1_t old;
  if (!SafeDecode<calibration_v1_t>(data, size, &old)) return false;
  *msg = calibration_t{};
  msg->utime = old.utime;
  msg->seq = old.seq;
  msg->scan_id = old.scan_id;
  msg->station = old.station;
  msg->session = old.session;
  msg->source = old.source;
  msg->camera = old.camera;
  msg->projector = old.projector;
  const Calibration defaults;
  msg->min_z_mm = defaults.min_z_mm;
  msg->max_z_mm = defaults.max_z_mm;
  msg->scale_error_percent = defaults.scale_error_percent;
  return true;
}

bool SafeDecode(const void* data, int64_t size, pattern_shown_t* msg) {
  if (SafeDecode<pattern_shown_t>(data, size, msg)) return true;
  pattern_shown_v1_t old;
  if (!SafeDecode<pattern_shown_v1_t>(data, size, &old)) return false;
  *msg = pattern_shown_t{};
  msg->utime = old.utime;
  msg->seq = old.seq;
  msg->scan_id = old.scan_id;
  msg->station = old.station;
  msg->session = old.session;
  msg->pattern_index = old.pattern_index;
  msg->pattern_count = old.pattern_count;
  msg->projector_width = old.projector_width;
  msg->projector_height = old.projector_height;
  msg->pattern = old.pattern;
  msg->light_count = old.light_count;
  msg->light = old.light;
  return true;  // handed_utime 0: not said.
}

bool SafeDecode(const void* data, int64_t size, texture_t* msg) {
  if (SafeDecode<texture_t>(data, size, msg)) return true;
  texture_v1_t old;
  if (!SafeDecode<texture_v1_t>(data, size, &old)) return false;
  *msg = texture_t{};
  msg->utime = old.utime;
  msg->seq = old.seq;
  msg->station = old.station;
  msg->scan_id = old.scan_id;
  msg->chunk_index = old.chunk_index;
  msg->chunk_count = old.chunk_count;
  msg->width = old.width;
  msg->height = old.height;
  msg->row_begin = old.row_begin;
  msg->row_count = old.row_count;
  msg->channels = old.channels;
  msg->bits = 8;  // All it could be.
  msg->size = old.size;
  msg->data = std::move(old.data);
  msg->light_count = old.light_count;
  msg->light = old.light;
  return true;
}

}  // namespace vellum::station
