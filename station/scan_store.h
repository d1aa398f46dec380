// A scan's captures on their way to disk: the set of CAPTURE messages of one scan (checked
// for consistency, with the missing ones named), and the scan's folder (raw captures as an LCM
// log and as the scan directory of docs/formats.md, written as they arrive, before any processing).
#pragma once

#include <cstdint>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

// The encoded bytes of a message (what the bus and the logs carry).
template <class Msg>
std::vector<uint8_t> Encode(const Msg& msg) {
  std::vector<uint8_t> bytes(msg.getEncodedSize());
  msg.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}

// <data>/scan-<id>[-<slug>]/raw (the scan directory, captures.lcmlog, calibration.yaml) and
// .../results (what `vellum process` writes). The slug is the scan's identity made a readable,
// safe name (IdentitySlug: "scan-1732971234567890-MS-12_3_recto"); a scan without one is
// "scan-<id>". The id alone finds the folder.
struct ScanFolder {
  std::string root;
  // The folder of scan `scan_id` that exists (with or without a slug; set aside in retaken/ or
  // not), else where a scan without a slug would go.
  static ScanFolder For(const std::string& data_dir, int64_t scan_id);
  // Where a new scan goes, named with `slug` ("" for none).
  static ScanFolder New(const std::string& data_dir, int64_t scan_id, const std::string& slug);
  std::string raw() const;
  std::string results() const;
  std::string log() const;          // raw/captures.lcmlog
  std::string calibration() const;  // raw/calibration.yaml
  std::string pending() const;      // pending: the supervisor's ledger (station/supervisor.h)
  std::string failed() const;       // raw/failed.txt: the scan was given up, and why
  std::string scan_yaml() const;    // raw/scan.yaml: written once the scan is recorded whole
};

// The scan id of a folder's name ("scan-<id>" or "scan-<id>-<slug>") and its slug (if asked);
// 0 for a name that is not a scan folder's.
int64_t ScanFolderId(const std::string& name, std::string* slug = nullptr);

// A retake: the earlier attempts of the same folio (the folders named with `slug` under another
// id, not pending) are moved into <data>/retaken/, kept whole and never deleted, so that the
// newest attempt of each folio is the one in <data>. Returns the folders' new paths. A scan
// without a slug has no earlier attempts.
std::vector<std::string> SetAsideEarlierAttempts(const std::string& data_dir, int64_t scan_id,
                                                 const std::string& slug);

// A scan given up (recording failed, captures stopped, a duplicate capture, or parked by the
// supervisor after failing twice): raw/failed.txt holds the reason, and the scan is never
// reopened or sent down the chain again.
Status MarkFailed(const ScanFolder& folder, const std::string& why);

// The most patterns a scan may have (a CAPTURE or SCAN_STARTED claiming more is refused).
inline constexpr int kMaxPatterns = 1000;

// What a CAPTURE claims about itself, checked before anything is written: a pattern count of 1
// to kMaxPatterns, 0 to kMaxLights extra lights, its index -1 (the texture), a pattern's, or
// pattern count + k for extra light k (which it names, ValidLightName; a pattern or the texture
// names none), a projector of 2 to 65536 pixels each way. A capture that fails is refused whole
// (never recorded: a scan's log holds only captures that belong in it).
Status CheckCapture(const capture_t& c);
// Whether a capture claims to be one of its scan's captures (a count of 1 to kMaxPatterns, its
// index -1 or within it and its lights): one that does, and is bad, may stand in for the scan's
// real capture of that pattern (its projector moves on); one that does not never does.
bool ClaimsAPattern(const capture_t& c);

// The captures of one scan, as they arrive.
class CaptureSet {
 public:
  // Checks the capture against the scan (ids, counts, projector size, image size) and keeps
  // its image. Errors name the scan and pattern.
  Status Add(const capture_t& capture);
  bool Started() const { return count_ >= 0; }
  bool Complete() const;
  int64_t scan_id() const { return scan_id_; }
  int Received() const { return received_; }
  int Expected() const { return count_ + lights_ + 1; }  // Texture + patterns + lights.
  // Whether the capture of pattern_index (-1: texture; count + k: light k) is in.
  bool Has(int pattern_index) const {
    return Started() && pattern_index >= -1 && pattern_index < count_ + lights_ &&
           have_[pattern_index + 1];
  }
  // "texture, frames 3, 7 of 54 missing".
  std::string Missing() const;
  // The whole scan (only when Complete()); without its frames when they are not kept.
  Scan ToScan() const;
  // Whether Add keeps the frames' images (the default). A decoder that takes each frame up as
  // it comes, and reads them from the scan's folder when it must, keeps none: turning it off
  // lets go of those kept so far.
  void KeepFrames(bool keep);

 private:
  int64_t scan_id_ = 0;
  int count_ = -1, lights_ = 0, received_ = 0;
  cv::Size projector_, camera_;
  cv::Mat texture_;
  std::vector<cv::Mat> frames_;
  std::vector<PatternSpec> specs_;
  std::vector<ScanLight> light_images_;  // Extra light k, with its image (always kept).
  std::vector<bool> have_;               // [0] texture, [k + 1] frame k, [count + k + 1] light k.
  bool keep_frames_ = true;
};

// A data folder's lock (<data>/.vellum-decoder.lock, flock): one decoder records into a data
// folder, or two stations sharing one by mistake would write every capture twice. The kernel
// releases it when the holder dies, so a killed decoder never blocks its restart.
class DataLock {
 public:
  DataLock() = default;
  ~DataLock();
  DataLock(const DataLock&) = delete;
  DataLock& operator=(const DataLock&) = delete;
  // Takes the lock; an error names the folder and the holder's pid when it is taken.
  Status Take(const std::string& data_dir, const std::string& process);

 private:
  int fd_ = -1;
};

// Cuts a torn last event off an LCM log: a process killed in the middle of writing one, or a
// disk that filled, leaves a partial event, and LCM's reader sees nothing of what is appended
// after it. Every whole event stays. Sets *cut to the bytes removed (0 for a sound log or none).
Status TrimTornTail(const std::string& path, int64_t* cut);

// The scan's log, raw/captures.lcmlog, written on the LCM thread the moment a message
// arrives (an append and a flush: a crash of the process loses nothing it has received).
// Logs are only ever appended to; before appending to an existing log its torn last event,
// if any, is cut off (TrimTornTail), so that what follows stays readable.
class CaptureLog {
 public:
  Status Append(const ScanFolder& folder, int64_t scan_id, const std::string& channel,
                int64_t utime, const std::vector<uint8_t>& bytes);
  void Close();
  // Bytes of a torn event the last Append cut off as it opened the log (for the daemon's log).
  int64_t trimmed() const { return trimmed_; }

 private:
  int64_t trimmed_ = 0;
  int64_t scan_id_ = 0;
  std::string path_;
  std::unique_ptr<lcm::LogFile> log_;
};

// The rest of a scan's folder, on the worker thread: each capture as raw/texture.png,
// raw/frame_NNN.png or raw/light_<name>.png, raw/calibration.yaml, and raw/scan.yaml once
// complete. Each file, and the log as it grows, is hashed as it is written (while the next
// frames arrive), and the hashes kept in the scan's recorded-sha256.txt once it is complete,
// so that the manifest written when it is restored need not read raw/ again (io/manifest.h).
class ScanRecorder {
 public:
  // Opens the scan's folder. When its log already holds captures of this scan that were not
  // processed (the decoder restarted in the middle of the scan), they are taken up: added to
  // *resumed (*count of them), their images written if missing and hashed (as Write hashes
  // what comes next: io/manifest.h HashRecord); and its SCAN_STARTED (the
  // identity and leaf hint it carried), into *started.
  Status Open(const ScanFolder& folder, int64_t scan_id, CaptureSet* resumed, int* count,
              scan_started_t* started);
  Status Write(const capture_t& capture, const cv::Mat& image);
  Status Write(const calibration_t& calibration);
  Status Finish(const Scan& scan);

 private:
  // Hashes `path` (in raw/) as written, and what the log gained: a file that cannot be hashed
  // now is hashed by the manifest.
  void Hash(const std::string& path);

  ScanFolder folder_;
  HashRecord hashes_;
};

}  // namespace vellum::station
