#include "station/books.h"

#include <filesystem>

#include "core/common/text.h"
#include "io/calibration_io.h"
#include "io/scan_io.h"
#include "station/messages.h"
#include "station/scan_store.h"

namespace vellum::station {
namespace {

constexpr size_t kKeepScans = 8;  // Per-scan inputs kept (a few scans in flight at most).

template <class T>
void KeepRecent(std::map<int64_t, T>* m) {
  while (m->size() > kKeepScans) m->erase(m->begin());  // Scan ids grow with time.
}

}  // namespace

CalibrationBook::CalibrationBook(Node* node, const Calibration* fallback,
                                 const std::string& data_dir)
    : node_(node), data_dir_(data_dir) {
  if (fallback) {
    has_fallback_ = true;
    fallback_ = *fallback;
  }
  node->Subscribe<calibration_t>(channel::kCalibration, [this](const calibration_t& msg) {
    if (msg.scan_id == 0) return;  // A station calibration: the projector's, for scans to come.
    {
      // A scan is processed with the calibration it started with (the one the decoder
      // recorded): a later CALIBRATION for it is refused, never used.
      std::lock_guard<std::mutex> lock(mutex_);
      if (by_scan_.count(msg.scan_id)) {
        node_->Count("calibrations refused");
        // Not an error of the scan (scan_id 0): the scan goes on, unchanged.
        node_->Error("scan " + std::to_string(msg.scan_id) + ": a second CALIBRATION (from " +
                     Printable(msg.source) + ") refused: the scan keeps the one it started with");
        return;
      }
    }
    Calibration c;
    const Status s = FromMessage(msg, &c);
    if (!s.ok()) {
      node_->Error("CALIBRATION of scan " + std::to_string(msg.scan_id) + ": " + s.message(),
                   msg.scan_id);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    by_scan_[msg.scan_id] = c;
    KeepRecent(&by_scan_);
    if (heard_) heard_(msg.scan_id, c);
  });
}

Status CalibrationBook::Get(int64_t scan_id, Calibration* calibration) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = by_scan_.find(scan_id);
    if (it != by_scan_.end()) {
      *calibration = it->second;
      return Status::Ok();
    }
  }
  const std::string recorded = ScanFolder::For(data_dir_, scan_id).calibration();
  if (!data_dir_.empty() && PathExists(recorded)) {
    const Status s = ReadCalibration(recorded, calibration);
    return s;
  }
  if (has_fallback_) {
    *calibration = fallback_;
    return Status::Ok();
  }
  return Status::Error("no CALIBRATION message for it, and no --calibration file configured");
}

TextureBook::TextureBook(Node* node, const std::string& data_dir, bool lights)
    : data_dir_(data_dir),
      assembler_(
          node, channel::kTexture,
          [](const texture_t& m, cv::Mat* texture) { return AddChunk(m, texture); },
          [this](int64_t id, cv::Mat* texture, const texture_t& last) {
            by_scan_[id] = *texture;
            KeepRecent(&by_scan_);
            light_count_[id] = last.light_count;
            KeepRecent(&light_count_);
            lights_.erase(id);  // A scan sent again: its lights come again after it.
            if (taken_) taken_(id, *texture);
          }) {
  if (!lights) return;
  light_assembler_ = std::make_unique<Assembler<texture_t, ScanLight>>(
      node, channel::kLightTexture,
      [](const texture_t& m, ScanLight* light) {
        if (light->image.empty()) {
          const Status s = FromMessage(m.light, light);
          if (!s.ok()) return s;
        } else if (m.light.name != light->name) {
          return Status::Error("LIGHT_TEXTURE: chunk " + std::to_string(m.chunk_index) +
                               " is of another light than the first");
        }
        return AddChunk(m, &light->image);
      },
      [this](int64_t id, ScanLight* light, const texture_t&) {
        std::vector<ScanLight>& list = lights_[id];
        KeepRecent(&lights_);
        for (ScanLight& earlier : list) {
          if (earlier.name == light->name) {
            earlier = *light;
            return;
          }
        }
        list.push_back(*light);
      });
}

Status TextureBook::GetLights(int64_t scan_id, std::vector<ScanLight>* lights) const {
  lights->clear();
  const auto count = light_count_.find(scan_id);
  if (count != light_count_.end()) {
    if (count->second == 0) return Status::Ok();
    const auto got = lights_.find(scan_id);
    if (got != lights_.end() && static_cast<int>(got->second.size()) == count->second) {
      *lights = got->second;
      return Status::Ok();
    }
  }
  // Not heard whole (a restart): as the decoder recorded them.
  const std::string raw = ScanFolder::For(data_dir_, scan_id).raw();
  Scan scan;
  const Status s = data_dir_.empty() ? Status::Error("no data folder") : ReadScanHeader(raw, &scan);
  if (!s.ok()) {
    return Status::Error("its extra lights (LIGHT_TEXTURE) never arrived whole, and " + raw +
                         " cannot give them: " + s.message());
  }
  *lights = scan.lights;
  return Status::Ok();
}

Status TextureBook::Get(int64_t scan_id, cv::Mat* texture) const {
  auto it = by_scan_.find(scan_id);
  if (it != by_scan_.end()) {
    *texture = it->second;
    return Status::Ok();
  }
  const std::string raw = ScanFolder::For(data_dir_, scan_id).raw();
  if (!data_dir_.empty() && ReadTexture(raw, texture).ok()) return Status::Ok();
  return Status::Error("its texture (TEXTURE) never arrived, and " + raw + " has none");
}

}  // namespace vellum::station
