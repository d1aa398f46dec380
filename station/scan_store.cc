#include "station/scan_store.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <utility>

#include "core/common/text.h"
#include "io/calibration_io.h"
#include "io/image_file.h"
#include "io/json.h"
#include "io/scan_io.h"
#include "station/messages.h"
#include "station/node.h"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {
namespace fs = std::filesystem;

ScanFolder ScanFolder::New(const std::string& data_dir, int64_t scan_id, const std::string& slug) {
  const std::string name = "scan-" + std::to_string(scan_id) + (slug.empty() ? "" : "-" + slug);
  return {(fs::path(data_dir) / name).string()};
}

int64_t ScanFolderId(const std::string& name, std::string* slug) {
  if (name.rfind("scan-", 0) != 0) return 0;
  char* stop = nullptr;
  const long long id = std::strtoll(name.c_str() + 5, &stop, 10);
  if (id <= 0 || (*stop != '\0' && *stop != '-')) return 0;
  if (slug) *slug = *stop == '-' ? std::string(stop + 1) : std::string();
  return id;
}

std::vector<std::string> SetAsideEarlierAttempts(const std::string& data_dir, int64_t scan_id,
                                                 const std::string& slug) {
  std::vector<std::string> moved;
  if (slug.empty()) return moved;
  std::error_code ec;
  std::vector<fs::path> earlier;
  for (fs::directory_iterator it(data_dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::string name_slug;
    const int64_t id = ScanFolderId(it->path().filename().string(), &name_slug);
    if (id == 0 || id == scan_id || name_slug != slug || !it->is_directory(ec)) continue;
    if (PathExists((it->path() / "pending").string())) continue;  // Still on its way.
    earlier.push_back(it->path());
  }
  const fs::path aside = fs::path(data_dir) / "retaken";
  for (const fs::path& from : earlier) {
    fs::create_directories(aside, ec);
    const fs::path to = aside / from.filename();
    if (fs::exists(to, ec)) continue;  // Never over another.
    fs::rename(from, to, ec);
    if (!ec) moved.push_back(to.string());
  }
  return moved;
}

ScanFolder ScanFolder::For(const std::string& data_dir, int64_t scan_id) {
  const ScanFolder plain = New(data_dir, scan_id, "");
  std::error_code ec;
  if (fs::is_directory(plain.root, ec)) return plain;
  // A named folder: found by its prefix, and remembered (a scan's folder is looked up for each
  // of its captures; a name, once given, does not change), checked to be there still.
  static std::mutex mutex;
  static std::map<std::pair<std::string, int64_t>, std::string> known;
  const auto key = std::make_pair(data_dir, scan_id);
  {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = known.find(key);
    if (it != known.end() && fs::is_directory(it->second, ec)) return {it->second};
  }
  for (const fs::path& dir : {fs::path(data_dir), fs::path(data_dir) / "retaken"}) {
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      if (ScanFolderId(it->path().filename().string()) != scan_id || !it->is_directory(ec)) {
        continue;
      }
      std::lock_guard<std::mutex> lock(mutex);
      if (known.size() > 256) known.clear();
      known[key] = it->path().string();
      return {it->path().string()};
    }
    ec.clear();
  }
  return plain;
}
std::string ScanFolder::raw() const { return (fs::path(root) / "raw").string(); }
std::string ScanFolder::results() const { return (fs::path(root) / "results").string(); }
std::string ScanFolder::log() const { return (fs::path(raw()) / "captures.lcmlog").string(); }
std::string ScanFolder::calibration() const {
  return (fs::path(raw()) / "calibration.yaml").string();
}

std::string ScanFolder::pending() const { return (fs::path(root) / "pending").string(); }
std::string ScanFolder::failed() const { return (fs::path(raw()) / kGivenUpName).string(); }
std::string ScanFolder::scan_yaml() const { return (fs::path(raw()) / "scan.yaml").string(); }

Status MarkFailed(const ScanFolder& folder, const std::string& why) {
  return WriteTextFile(folder.failed(), why + "\n");
}

bool ClaimsAPattern(const capture_t& c) {
  return c.pattern_count > 0 && c.pattern_count <= kMaxPatterns && c.light_count >= 0 &&
         c.light_count <= kMaxLights && c.pattern_index >= -1 &&
         c.pattern_index < c.pattern_count + c.light_count;
}

Status CheckCapture(const capture_t& c) {
  const std::string where =
      "scan " + std::to_string(c.scan_id) + ", pattern " + std::to_string(c.pattern_index);
  if (c.pattern_count <= 0 || c.pattern_count > kMaxPatterns) {
    return Status::Error(where + ": pattern_count " + std::to_string(c.pattern_count) +
                         " is not valid");
  }
  if (c.light_count < 0 || c.light_count > kMaxLights) {
    return Status::Error(where + ": light_count " + std::to_string(c.light_count) + " is not 0.." +
                         std::to_string(kMaxLights));
  }
  if (!ClaimsAPattern(c)) {
    return Status::Error(where + ": pattern_index outside -1.." +
                         std::to_string(c.pattern_count + c.light_count - 1));
  }
  if (c.pattern_index >= c.pattern_count) {
    ScanLight light;
    const Status s = FromMessage(c.light, &light);
    if (!s.ok()) return Status::Error(where + " (an extra light): " + s.message());
  } else if (!c.light.name.empty()) {
    return Status::Error(where + ": names a light, but is the texture or a pattern");
  }
  if (c.projector_width < 2 || c.projector_height < 2 || c.projector_width > kMaxProjectorExtent ||
      c.projector_height > kMaxProjectorExtent) {
    return Status::Error(where + ": projector size " + std::to_string(c.projector_width) + "x" +
                         std::to_string(c.projector_height) + " is not valid");
  }
  return Status::Ok();
}

Status CaptureSet::Add(const capture_t& c) {
  const std::string where =
      "scan " + std::to_string(c.scan_id) + ", pattern " + std::to_string(c.pattern_index);
  Status s = CheckCapture(c);
  if (!s.ok()) return s;
  cv::Mat image;
  s = FromMessage(c.image, &image);
  if (!s.ok()) return Status::Error(where + ": " + s.message());
  PatternSpec spec;
  s = FromMessage(c.pattern, &spec);
  if (!s.ok()) return Status::Error(where + ": " + s.message());
  const cv::Size projector(c.projector_width, c.projector_height);
  if (!Started()) {
    if (projector.width <= 0 || projector.height <= 0) {
      return Status::Error(where + ": bad projector size");
    }
    scan_id_ = c.scan_id;
    count_ = c.pattern_count;
    lights_ = c.light_count;
    projector_ = projector;
    camera_ = image.size();
    frames_.assign(count_, cv::Mat());
    specs_.assign(count_, PatternSpec());
    light_images_.assign(lights_, ScanLight());
    have_.assign(count_ + lights_ + 1, false);
  } else if (c.scan_id != scan_id_ || c.pattern_count != count_ || c.light_count != lights_ ||
             projector != projector_) {
    return Status::Error(where + ": does not match the scan's " + std::to_string(count_) +
                         " patterns and " + std::to_string(lights_) + " extra lights for a " +
                         SizeText(projector_) + " projector");
  }
  if (image.size() != camera_) {
    return Status::Error(where + ": image is " + SizeText(image.size()) + ", the scan's are " +
                         SizeText(camera_));
  }
  if (have_[c.pattern_index + 1]) return Status::Error(where + ": captured twice");
  if (c.pattern_index >= count_) {
    ScanLight light;
    s = FromMessage(c.light, &light);  // Checked by CheckCapture.
    if (!s.ok()) return Status::Error(where + ": " + s.message());
    for (int k = 0; k < lights_; ++k) {
      if (have_[count_ + k + 1] && light_images_[k].name == light.name) {
        return Status::Error(where + ": the light '" + light.name + "' is the scan's light " +
                             std::to_string(k) + " already");
      }
    }
    light.image = image;
    light_images_[c.pattern_index - count_] = light;
  } else if (c.pattern_index == -1) {
    texture_ = image;
  } else {
    if (image.channels() != 1) {
      return Status::Error(where + ": pattern frames must be gray (GREY)");
    }
    if (keep_frames_) frames_[c.pattern_index] = image;
    specs_[c.pattern_index] = spec;
  }
  have_[c.pattern_index + 1] = true;
  ++received_;
  return Status::Ok();
}

bool CaptureSet::Complete() const { return Started() && received_ == Expected(); }

std::string CaptureSet::Missing() const {
  std::string list;
  int n = 0;
  for (int k = 0; k < Expected(); ++k) {
    if (have_[k]) continue;
    const std::string what = k == 0        ? std::string("texture")
                             : k <= count_ ? std::to_string(k - 1)
                                           : "light " + std::to_string(k - 1 - count_);
    if (n < 8) list += (n ? ", " : "") + what;
    ++n;
  }
  if (n > 8) list += ", ...";
  return std::to_string(n) + " of " + std::to_string(Expected()) + " captures missing (" + list +
         ")";
}

Scan CaptureSet::ToScan() const {
  Scan scan;
  scan.sequence.projector_size = projector_;
  scan.sequence.patterns = specs_;
  scan.camera_size = camera_;
  scan.texture = texture_;
  if (keep_frames_) scan.frames = frames_;
  scan.lights = light_images_;
  return scan;
}

void CaptureSet::KeepFrames(bool keep) {
  keep_frames_ = keep;
  if (!keep) {
    for (cv::Mat& frame : frames_) frame.release();
  }
}

DataLock::~DataLock() {
  if (fd_ >= 0) close(fd_);  // Releases the flock.
}

Status DataLock::Take(const std::string& data_dir, const std::string& process) {
  Status s = MakeDirectories(data_dir);
  if (!s.ok()) return s;
  const std::string path = (fs::path(data_dir) / ".vellum-decoder.lock").string();
  const int fd = open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return Status::Error(path + ": cannot open: " + std::strerror(errno));
  if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
    char holder[32] = {0};
    const ssize_t n = pread(fd, holder, sizeof(holder) - 1, 0);
    close(fd);
    std::string pid = n > 0 ? std::string(holder, static_cast<size_t>(n)) : std::string("?");
    while (!pid.empty() && (pid.back() == '\n' || pid.back() == ' ')) pid.pop_back();
    return Status::Error(data_dir + " is being recorded into by another " + process + " (pid " +
                         Printable(pid, 20) + ", holding " + path +
                         "): one decoder per data folder; two stations need a folder each");
  }
  // The pid only makes another decoder's message clearer: the lock holds without it.
  const std::string mine = std::to_string(getpid()) + "\n";
  if (ftruncate(fd, 0) == 0) (void)!pwrite(fd, mine.data(), mine.size(), 0);
  fd_ = fd;
  return Status::Ok();
}

Status TrimTornTail(const std::string& path, int64_t* cut) {
  *cut = 0;
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) return Status::Ok();  // No log yet.
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot read the scan's log");
  // Each event: sync word, event number, timestamp, channel length, data length (big-endian),
  // then the channel and the data.
  constexpr uint32_t kSync = 0xEDA1DA01u;
  constexpr int64_t kHeader = 4 + 8 + 8 + 4 + 4;
  auto be32 = [](const unsigned char* b) {
    return (uint32_t{b[0]} << 24) | (uint32_t{b[1]} << 16) | (uint32_t{b[2]} << 8) | b[3];
  };
  const int64_t total = static_cast<int64_t>(size);
  int64_t end = 0;  // End of the whole events read so far.
  unsigned char h[kHeader];
  while (end < total) {
    if (end + kHeader > total) break;  // A torn header.
    in.seekg(end);
    if (!in.read(reinterpret_cast<char*>(h), kHeader)) {
      return Status::Error(path + ": cannot read the scan's log");
    }
    const int64_t channel_len = static_cast<int32_t>(be32(h + 20));
    const int64_t data_len = static_cast<int32_t>(be32(h + 24));
    // Not an event header: not a torn tail but damage inside the log. Nothing is cut.
    if (be32(h) != kSync || channel_len < 0 || data_len < 0) return Status::Ok();
    if (end + kHeader + channel_len + data_len > total) break;  // A torn body.
    end += kHeader + channel_len + data_len;
  }
  if (end == total) return Status::Ok();
  in.close();
  fs::resize_file(path, static_cast<uintmax_t>(end), ec);
  if (ec) return Status::Error(path + ": cannot cut off its torn last event: " + ec.message());
  *cut = total - end;
  return Status::Ok();
}

Status CaptureLog::Append(const ScanFolder& folder, int64_t scan_id, const std::string& channel,
                          int64_t utime, const std::vector<uint8_t>& bytes) {
  trimmed_ = 0;
  if (!log_ || scan_id != scan_id_) {
    Close();
    Status s = MakeDirectories(folder.raw());
    if (!s.ok()) return s;
    path_ = folder.log();
    s = TrimTornTail(path_, &trimmed_);
    if (!s.ok()) return s;
    auto log = std::make_unique<lcm::LogFile>(path_, "a");
    if (!log->good()) return Status::Error(path_ + ": cannot open the scan's log");
    log_ = std::move(log);
    scan_id_ = scan_id;
  }
  lcm::LogEvent event;
  event.eventnum = 0;
  event.timestamp = utime;
  event.channel = channel;
  event.datalen = static_cast<int32_t>(bytes.size());
  event.data = const_cast<uint8_t*>(bytes.data());
  if (log_->writeEvent(&event) != 0 || fflush(log_->getFilePtr()) != 0) {
    Close();  // Reopened (appending) for the next message.
    return Status::Error(path_ + ": cannot write (disk full?)");
  }
  return Status::Ok();
}

void CaptureLog::Close() {
  log_.reset();
  scan_id_ = 0;
}

// The capture's file in the scan directory (docs/formats.md), and its writer: the texture and the
// lights' images as they came, a pattern's frame within the camera's frame interval
// (WriteFrameImage).
static std::string ImageName(const capture_t& c) {
  if (c.pattern_index >= c.pattern_count) return LightFileName(c.light.name);
  return c.pattern_index < 0 ? "texture.png" : FrameName(c.pattern_index);
}

static Status WriteCaptureImage(const std::string& path, const capture_t& c, const cv::Mat& image) {
  const bool frame = c.pattern_index >= 0 && c.pattern_index < c.pattern_count;
  return frame ? WriteFrameImage(path, image) : WriteImage(path, image);
}

void ScanRecorder::Hash(const std::string& path) {
  const auto rel = [&](const std::string& p) {
    return fs::path(p).lexically_relative(folder_.root).generic_string();
  };
  hashes_.Add(rel(path)).ok();
  if (PathExists(folder_.log())) hashes_.Grow(rel(folder_.log())).ok();
}

Status ScanRecorder::Open(const ScanFolder& folder, int64_t scan_id, CaptureSet* resumed,
                          int* count, scan_started_t* started_out) {
  folder_ = folder;
  hashes_ = HashRecord(folder.root);
  *count = 0;
  Status s = MakeDirectories(folder.raw());
  if (!s.ok()) return s;
  if (!PathExists(folder.log())) return Status::Ok();
  CaptureSet earlier;
  std::vector<capture_t> taken;
  {
    lcm::LogFile old(folder.log(), "r");
    for (const lcm::LogEvent* e = old.good() ? old.readNextEvent() : nullptr; e;
         e = old.readNextEvent()) {
      scan_started_t started;
      if (e->channel == channel::kScanStarted && SafeDecode(e->data, e->datalen, &started) &&
          started.scan_id == scan_id) {
        *started_out = started;
        continue;
      }
      capture_t c;
      if (e->channel != channel::kCapture || !SafeDecode(e->data, e->datalen, &c) ||
          c.scan_id != scan_id || earlier.Has(c.pattern_index)) {
        continue;
      }
      if (earlier.Add(c).ok()) taken.push_back(std::move(c));
    }
  }
  // A complete scan in the log was processed before: this is the scan again (a replay).
  if (earlier.Complete()) return Status::Ok();
  // Each capture's file written (or there already, from before a restart) and hashed, as the
  // captures that come next are.
  for (const capture_t& c : taken) {
    const std::string path = (fs::path(folder.raw()) / ImageName(c)).string();
    cv::Mat image;
    if (!PathExists(path) && FromMessage(c.image, &image).ok()) {
      s = WriteCaptureImage(path, c, image);
      if (!s.ok()) return s;
    }
    if (PathExists(path)) Hash(path);
  }
  *resumed = earlier;
  *count = static_cast<int>(taken.size());
  return Status::Ok();
}

Status ScanRecorder::Write(const capture_t& capture, const cv::Mat& image) {
  const std::string path = (fs::path(folder_.raw()) / ImageName(capture)).string();
  const Status s = WriteCaptureImage(path, capture, image);
  if (s.ok()) Hash(path);
  return s;
}

Status ScanRecorder::Write(const calibration_t& calibration) {
  Calibration c;
  Status s = FromMessage(calibration, &c);
  if (s.ok()) s = WriteCalibration(folder_.calibration(), c);
  if (s.ok()) Hash(folder_.calibration());
  return s;
}

Status ScanRecorder::Finish(const Scan& scan) {
  const Status s = WriteScanYaml(folder_.raw(), scan);
  if (!s.ok()) return s;
  Hash(folder_.scan_yaml());
  hashes_.Save().ok();  // Without it the manifest reads raw/ again: slower, as sound.
  return s;
}

}  // namespace vellum::station
