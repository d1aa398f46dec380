// What a processing daemon needs of a scan besides its product: the calibration (CALIBRATION,
// from the projector at the start of the scan) and the texture (TEXTURE, from the decoder as
// it sends the scan down the chain). A daemon that restarted after they went by takes them
// from the scan's raw folder on disk, where the decoder recorded them (docs/station.md,
// "The supervisor, and what lives where").
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "core/patterns/scan.h"
#include "station/assembler.h"
#include "station/node.h"

namespace vellum::station {

// The calibration of each scan, from its first CALIBRATION message (a later one for the same
// scan is refused, and scan_id 0 is the projector's business); for a scan whose message this
// process has not seen (it restarted since), the one the decoder recorded in the scan's folder
// under `data_dir`; else the fallback.
class CalibrationBook {
 public:
  // `fallback` may be null (then a scan without a CALIBRATION message fails).
  CalibrationBook(Node* node, const Calibration* fallback, const std::string& data_dir);
  Status Get(int64_t scan_id, Calibration* calibration) const;
  // Calls `heard` (on the LCM thread) with each scan's calibration as it is taken: a daemon
  // prepares what it makes from it while the scan is captured (the triangulator's rays).
  void OnTaken(std::function<void(int64_t scan_id, const Calibration&)> heard) {
    std::lock_guard<std::mutex> lock(mutex_);
    heard_ = std::move(heard);
  }

 private:
  Node* node_;
  std::string data_dir_;
  bool has_fallback_ = false;
  Calibration fallback_;
  mutable std::mutex mutex_;  // Guards by_scan_: filled on the LCM thread, read on the worker.
  std::map<int64_t, Calibration> by_scan_;
  std::function<void(int64_t, const Calibration&)> heard_;
};

// The texture of each recent scan, reassembled from TEXTURE chunks, and with `lights` the images
// under its extra lights (LIGHT_TEXTURE); for a scan whose texture or lights this process has not
// seen whole (it restarted since), those the decoder recorded under `data_dir`. Worker thread
// only (the chunks are reassembled there, in order with the products that need them).
class TextureBook {
 public:
  TextureBook(Node* node, const std::string& data_dir, bool lights = false);
  Status Get(int64_t scan_id, cv::Mat* texture) const;
  // Calls `taken` (on the worker thread) with each scan's texture as it comes whole over the bus:
  // a daemon begins what needs only the texture while the scan is still captured.
  void OnTaken(std::function<void(int64_t scan_id, const cv::Mat& texture)> taken) {
    taken_ = std::move(taken);
  }
  // The scan's extra lights with their images, in the scan's order (none for a scan without).
  Status GetLights(int64_t scan_id, std::vector<ScanLight>* lights) const;
  // About once a second: gives up a texture whose chunks stopped coming.
  void Tick() {
    assembler_.Tick();
    if (light_assembler_) light_assembler_->Tick();
  }

 private:
  std::string data_dir_;
  std::map<int64_t, cv::Mat> by_scan_;
  std::function<void(int64_t, const cv::Mat&)> taken_;
  std::map<int64_t, int> light_count_;  // What each TEXTURE announced.
  std::map<int64_t, std::vector<ScanLight>> lights_;
  Assembler<texture_t, cv::Mat> assembler_;
  std::unique_ptr<Assembler<texture_t, ScanLight>> light_assembler_;
};

}  // namespace vellum::station
