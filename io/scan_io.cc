#include "io/scan_io.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "core/common/text.h"
#include "core/outline/outline.h"
#include "io/image_file.h"
#include "io/vips.h"
#include "io/yaml_guard.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

constexpr char kScanYaml[] = "scan.yaml";
constexpr char kTexture[] = "texture.png";
constexpr char kFormat[] = "vellum-scan";

// A PNG's size and sample depth from its header (the IHDR chunk that follows the signature),
// read before the image is decoded: a header may claim gigabytes. False if the file is not a
// PNG (OpenCV then judges it).
bool PngHeader(const std::string& path, uint32_t* width, uint32_t* height, int* bit_depth) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  unsigned char b[26];
  const size_t n = std::fread(b, 1, sizeof b, f);
  std::fclose(f);
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n < sizeof b || std::memcmp(b, kSignature, 8) != 0 || std::memcmp(b + 12, "IHDR", 4) != 0) {
    return false;
  }
  auto be32 = [&](int at) {
    return (uint32_t{b[at]} << 24) | (uint32_t{b[at + 1]} << 16) | (uint32_t{b[at + 2]} << 8) |
           uint32_t{b[at + 3]};
  };
  *width = be32(16);
  *height = be32(20);
  *bit_depth = b[24];
  return true;
}

// What an image file's header says, before its pixels are decoded: a PNG's size (*size), or an
// empty size for another format OpenCV reads; an error for a claim too large, a PNG deeper than
// `max_bits`, or a file no reader knows.
Status CheckImageHeader(const std::string& path, cv::Size* size, int max_bits = 8) {
  *size = cv::Size();
  uint32_t width = 0, height = 0;
  int bit_depth = 0;
  if (!PngHeader(path, &width, &height, &bit_depth)) {
    // Another format: one vellum reads through libvips, judged when it is read.
    return CheckVipsLoader(path);
  }
  // The largest image a scan may hold, each side: kMaxImageSide (yaml_guard.h).
  constexpr uint32_t kMaxSide = kMaxImageSide;
  if (width == 0 || height == 0 || width > kMaxSide || height > kMaxSide) {
    return Status::Error(path + ": its header claims " + std::to_string(width) + "x" +
                         std::to_string(height) + " pixels (at most " +
                         std::to_string(kMaxImageSide) + " each way); not read");
  }
  if (bit_depth > max_bits) {
    return Status::Error(path + ": must be " + (max_bits == 8 ? "an 8" : "an 8- or 16") +
                         "-bit image (its header says " + std::to_string(bit_depth) +
                         "-bit); not read");
  }
  *size = cv::Size(static_cast<int>(width), static_cast<int>(height));
  return Status::Ok();
}

// An image of 8 bits a sample, or of 8 or 16 when `max_bits` is 16 (the texture of a camera
// that gives more than 8).
// `size_fits` (if given) judges the size the file's header claims before a pixel is decoded (a
// small PNG can claim 16384 x 16384 and take gigabytes to decode).
Status ReadImageFile(const std::string& path, cv::Mat* image, int max_bits = 8,
                     const std::function<Status(cv::Size)>& size_fits = nullptr) {
  const Status readable = CheckReadable(path);
  if (!readable.ok()) return readable;
  cv::Size claimed;
  const Status header = CheckImageHeader(path, &claimed, max_bits);
  if (!header.ok()) return header;
  if (size_fits && !claimed.empty()) {
    const Status fits = size_fits(claimed);
    if (!fits.ok()) return fits;
  }
  cv::Mat img;
  const Status read = ReadImage(path, &img);
  if (!read.ok()) return read;
  if (img.depth() != CV_8U && !(max_bits == 16 && img.depth() == CV_16U)) {
    return Status::Error(
        path + (max_bits == 8 ? ": must be an 8-bit image" : ": must be an 8- or 16-bit image"));
  }
  *image = img;
  return Status::Ok();
}

}  // namespace

std::string FrameName(int index) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "frame_%03d.png", index);
  return buf;
}

std::string PatternName(int index) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "pattern_%03d.png", index);
  return buf;
}

bool PathExists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::exists(path, ec);
}

Status MakeDirectories(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::Error(dir + ": cannot create directory: " + ec.message());
  return Status::Ok();
}

Status WriteFrameImage(const std::string& path, const cv::Mat& frame) {
  if (frame.type() != CV_8UC1) return WriteImage(path, frame);
  return WritePng(path, frame, PngWriting{0, false});
}

std::string LightFileName(const std::string& name) { return "light_" + name + ".png"; }

bool ReadGivenUp(const std::string& raw_dir, std::string* why) {
  std::ifstream in(raw_dir + "/" + kGivenUpName);
  if (!in) return false;
  std::string line;
  std::getline(in, line);
  if (why != nullptr) *why = line;
  return true;
}

Status WriteScanYaml(const std::string& dir, const Scan& header) {
  const PatternSequence& sequence = header.sequence;
  const cv::Size camera_size = header.camera_size;
  const cv::Rect& leaf_hint = header.leaf_hint;
  const std::vector<ScanLight>& lights = header.lights;
  const std::string path = (fs::path(dir) / kScanYaml).string();
  try {
    cv::FileStorage out(path, cv::FileStorage::WRITE);
    if (!out.isOpened()) return Status::Error(path + ": cannot write");
    out << "format" << kFormat;
    out << "version" << 1;
    out << "projector_size" << sequence.projector_size;
    if (camera_size.area() > 0) out << "camera_size" << camera_size;
    ForEachIdentityField(header.identity, [&](const char* key, const std::string& value) {
      if (!value.empty()) out << key << value;
    });
    if (!leaf_hint.empty()) {
      out << "leaf_hint"
          << std::vector<int>{leaf_hint.x, leaf_hint.y, leaf_hint.width, leaf_hint.height};
    }
    if (header.object != ObjectKind::kAuto) out << "object" << ToString(header.object);
    if (header.live_off_view != 0) {
      out << "live_off_view"
          << "[:";  // Flow style: [ right, top ].
      for (int k = 0; k < kViewSideCount; ++k) {
        if (header.live_off_view & (1 << k)) out << kViewSideNames[k];
      }
      out << "]";
    }
    out << "texture" << kTexture;
    if (!lights.empty()) {
      out << "lights"
          << "[";
      for (const ScanLight& light : lights) {
        out << "{"
            << "name" << light.name;
        if (light.directed())
          out << "direction" << std::vector<double>(light.direction.val, light.direction.val + 3);
        out << "}";
      }
      out << "]";
    }
    out << "patterns"
        << "[";
    for (const PatternSpec& s : sequence.patterns) {
      out << "{"
          << "kind" << ToString(s.kind);
      if (s.kind == PatternKind::kGray) {
        out << "axis" << ToString(s.axis) << "bit" << s.bit << "inverted" << (s.inverted ? 1 : 0);
      } else if (s.kind == PatternKind::kPhase) {
        out << "axis" << ToString(s.axis) << "step" << s.step << "steps" << s.steps << "period_px"
            << s.period_px;
      }
      out << "}";
    }
    out << "]";
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": cannot write: " + e.what());
  }
  return Status::Ok();
}

namespace {

// A sequence of the view's sides by name (`[right, top]`; absent or empty: none) into *sides.
Status ReadViewSides(const cv::FileNode& n, const std::string& path, int* sides) {
  *sides = 0;
  if (n.empty() || n.isNone()) return Status::Ok();
  const Status bad = Status::Error(
      path +
      ": key 'live_off_view' must be a sequence of the view's sides (left, right, top, "
      "bottom), each at most once");
  if (!n.isSeq() || n.size() > kViewSideCount) return bad;
  for (const cv::FileNode& side : n) {
    const int bit = side.isString() ? ViewSideOf(static_cast<std::string>(side)) : 0;
    if (bit == 0 || (*sides & bit)) return bad;
    *sides |= bit;
  }
  return Status::Ok();
}

// The `lights` sequence of a scan.yaml or a station's lights file (at `path`, for messages): each
// {name, direction} (direction optional), at most kMaxLights, and with `channels` its optional
// `channel` (-1 when not given).
Status ReadLightList(const cv::FileNode& list, const std::string& path,
                     std::vector<ScanLight>* lights, std::vector<int>* channels) {
  lights->clear();
  if (channels) channels->clear();
  if (!list.empty() && !list.isNone() && !list.isSeq()) {
    return Status::Error(path + ": key 'lights' must be a sequence of {name, direction}");
  }
  if (list.isSeq() && static_cast<int>(list.size()) > kMaxLights) {
    return Status::Error(path + ": " + std::to_string(list.size()) + " lights, at most " +
                         std::to_string(kMaxLights));
  }
  for (const cv::FileNode& n : list) {
    const std::string where = path + ": light " + std::to_string(lights->size());
    ScanLight light;
    if (!n.isMap() || !n["name"].isString() ||
        !ValidLightName(light.name = static_cast<std::string>(n["name"]))) {
      return Status::Error(where +
                           ": 'name' must be 1 to 32 of a-z, 0-9, '-' and '_', starting with "
                           "a letter or digit");
    }
    for (const ScanLight& earlier : *lights) {
      if (earlier.name == light.name) {
        return Status::Error(where + ": the name '" + light.name + "' is given twice");
      }
    }
    const cv::FileNode d = n["direction"];
    if (!d.empty() && !d.isNone()) {
      auto number = [](const cv::FileNode& x) { return x.isReal() || x.isInt(); };
      if (!d.isSeq() || d.size() != 3 || !number(d[0]) || !number(d[1]) || !number(d[2])) {
        return Status::Error(where + " ('" + light.name +
                             "'): 'direction' must be [ x, y, z ], towards the light");
      }
      const cv::Vec3d v(static_cast<double>(d[0]), static_cast<double>(d[1]),
                        static_cast<double>(d[2]));
      if (!UnitLightDirection(v, &light.direction)) {
        return Status::Error(where + " ('" + light.name +
                             "'): 'direction' must point up from the table (z > 0)");
      }
    }
    if (channels) {
      const cv::FileNode c = n["channel"];
      int channel = -1;
      if (!c.empty() && !c.isNone()) {
        if (!c.isInt() || static_cast<int>(c) < 0 || static_cast<int>(c) > 255) {
          return Status::Error(where + " ('" + light.name +
                               "'): 'channel' must be a whole number from 0 to 255");
        }
        channel = static_cast<int>(c);
      }
      channels->push_back(channel);
    }
    lights->push_back(light);
  }
  return Status::Ok();
}

}  // namespace

Status ReadLightsFile(const std::string& path, StationLights* out) {
  *out = StationLights();
  if (!fs::exists(path)) return Status::Error(path + ": file is missing");
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) return Status::Error(path + ": " + problem);
  try {
    cv::FileStorage in(path, cv::FileStorage::READ);
    if (!in.isOpened()) return Status::Error(path + ": cannot read (not YAML?)");
    const cv::FileNode list = in["lights"];
    if (!list.isSeq() || list.size() == 0) {
      return Status::Error(path +
                           ": key 'lights' must be a non-empty sequence of {name, "
                           "direction, channel}");
    }
    const Status s = ReadLightList(list, path, &out->lights, &out->channels);
    if (!s.ok()) return s;
    const cv::FileNode studio = in["studio_channel"];
    if (!studio.empty() && !studio.isNone()) {
      if (!studio.isInt() || static_cast<int>(studio) < 0 || static_cast<int>(studio) > 255) {
        return Status::Error(path + ": 'studio_channel' must be a whole number from 0 to 255");
      }
      out->studio_channel = static_cast<int>(studio);
    }
  } catch (const std::exception& e) {  // OpenCV's parser also throws std::length_error.
    return Status::Error(path + ": cannot parse: " + e.what());
  }
  return Status::Ok();
}

Status ReadScanYaml(const std::string& dir, Scan* header) {
  PatternSequence* sequence = &header->sequence;
  cv::Size* camera_size = &header->camera_size;
  const std::string path = (fs::path(dir) / kScanYaml).string();
  if (!fs::is_directory(dir)) return Status::Error(dir + ": not a directory");
  if (!fs::exists(path)) return Status::Error(path + ": file is missing");
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) return Status::Error(path + ": " + problem);
  cv::FileStorage in;
  try {
    if (!in.open(path, cv::FileStorage::READ)) return Status::Error(path + ": cannot open");
  } catch (const std::exception&) {
    return Status::Error(path + ": not valid YAML");
  }
  try {
    if (!in["format"].empty() && std::string(in["format"]) != kFormat) {
      return Status::Error(path + ": format is '" + std::string(in["format"]) + "', expected '" +
                           kFormat + "'");
    }
    auto read_size = [&](const char* key, cv::Size* size, bool required) {
      const cv::FileNode n = in[key];
      if (!required && (n.empty() || n.isNone())) {
        *size = cv::Size();
        return Status::Ok();
      }
      const std::string problem = ReadSizeNode(n, size);
      return problem.empty() ? Status::Ok()
                             : Status::Error(path + ": key '" + key + "' " + problem);
    };
    Status s = read_size("projector_size", &sequence->projector_size, true);
    if (!s.ok()) return s;
    s = read_size("camera_size", camera_size, false);
    if (!s.ok()) return s;
    {
      ScanIdentity read;
      std::string bad;  // The first key that is not text.
      ForEachIdentityField(read, [&](const char* key, std::string& value) {
        const cv::FileNode n = in[key];
        if (n.empty() || n.isNone()) return;
        if (n.isString()) {
          value = static_cast<std::string>(n);
        } else if (n.isInt()) {
          value = std::to_string(static_cast<int>(n));  // folio: 3
        } else if (bad.empty()) {
          bad = key;
        }
      });
      if (!bad.empty()) return Status::Error(path + ": key '" + bad + "' must be text");
      header->identity = SanitizedIdentity(read);
    }
    s = ReadLightList(in["lights"], path, &header->lights, nullptr);
    if (!s.ok()) return s;
    {
      cv::Rect* leaf_hint = &header->leaf_hint;
      *leaf_hint = cv::Rect();
      const cv::FileNode n = in["leaf_hint"];
      if (!n.empty() && !n.isNone()) {
        const Status bad = Status::Error(
            path + ": key 'leaf_hint' must be [ x, y, width, height ] in camera pixels, a region " +
            (camera_size->area() > 0 ? "of the " + std::to_string(camera_size->width) + "x" +
                                           std::to_string(camera_size->height) + " camera's view"
                                     : "of the camera's view"));
        if (!n.isSeq() || n.size() != 4) return bad;
        int v[4];
        for (int k = 0; k < 4; ++k) {
          if (!n[k].isInt()) return bad;
          v[k] = static_cast<int>(n[k]);
        }
        // Within the camera's view, or within the largest one when scan.yaml does not say
        // (the far edges summed in 64 bits: the numbers are the file's).
        const cv::Size view =
            camera_size->area() > 0 ? *camera_size : cv::Size(kMaxImageSide, kMaxImageSide);
        if (v[0] < 0 || v[1] < 0 || v[2] <= 0 || v[3] <= 0 || int64_t{v[0]} + v[2] > view.width ||
            int64_t{v[1]} + v[3] > view.height) {
          return bad;
        }
        const cv::Rect r(v[0], v[1], v[2], v[3]);
        *leaf_hint = r;
      }
    }
    header->object = ObjectKind::kAuto;
    const cv::FileNode object = in["object"];
    if (!object.empty() && !object.isNone() &&
        (!object.isString() ||
         !ParseObjectKind(static_cast<std::string>(object), &header->object))) {
      return Status::Error(path + ": key 'object' must be leaf, book or auto");
    }
    s = ReadViewSides(in["live_off_view"], path, &header->live_off_view);
    if (!s.ok()) return s;
    const cv::FileNode list = in["patterns"];
    if (!list.isSeq() || list.size() == 0) {
      return Status::Error(path + ": key 'patterns' must be a non-empty sequence");
    }
    sequence->patterns.clear();
    int index = 0;
    for (const cv::FileNode& n : list) {
      PatternSpec spec;
      const std::string where = path + ": pattern " + std::to_string(index);
      if (!n.isMap() ||
          !ParsePatternKind(n["kind"].isString() ? std::string(n["kind"]) : "", &spec.kind)) {
        return Status::Error(where + ": 'kind' must be white, black, gray or phase");
      }
      if (spec.kind == PatternKind::kGray || spec.kind == PatternKind::kPhase) {
        if (!ParseAxis(n["axis"].isString() ? std::string(n["axis"]) : "", &spec.axis)) {
          return Status::Error(where + ": 'axis' must be column or row");
        }
      }
      if (spec.kind == PatternKind::kGray) {
        if (!n["bit"].isInt() || !n["inverted"].isInt()) {
          return Status::Error(where + ": a gray pattern needs integer 'bit' and 'inverted'");
        }
        spec.bit = static_cast<int>(n["bit"]);
        spec.inverted = static_cast<int>(n["inverted"]) != 0;
        if (spec.bit < 0 || spec.bit > 20) return Status::Error(where + ": 'bit' out of range");
      } else if (spec.kind == PatternKind::kPhase) {
        if (!n["step"].isInt() || !n["steps"].isInt() || !n["period_px"].isInt()) {
          return Status::Error(where +
                               ": a phase pattern needs integer 'step', 'steps', 'period_px'");
        }
        spec.step = static_cast<int>(n["step"]);
        spec.steps = static_cast<int>(n["steps"]);
        spec.period_px = static_cast<int>(n["period_px"]);
        if (spec.steps < 3 || spec.step < 0 || spec.step >= spec.steps || spec.period_px < 4) {
          return Status::Error(where + ": phase step/steps/period_px out of range");
        }
      }
      sequence->patterns.push_back(spec);
      ++index;
    }
  } catch (const std::exception& e) {
    return Status::Error(path + ": malformed: " + e.what());
  }
  std::string why;
  if (!sequence->Check(&why)) return Status::Error(path + ": " + why);
  return Status::Ok();
}

Status ReadTexture(const std::string& dir, cv::Mat* texture) {
  return ReadImageFile((fs::path(dir) / kTexture).string(), texture, 16);
}

namespace {

// The camera's size: scan.yaml's camera_size, else the texture's.
cv::Size ExpectedSize(const Scan& scan) {
  return scan.camera_size.area() > 0 ? scan.camera_size : scan.texture.size();
}

// An image of the scan (`path`, of `size`) has the camera's size; the error says who said so.
Status CheckSize(const std::string& path, cv::Size size, const Scan& scan) {
  const cv::Size expected = ExpectedSize(scan);
  if (size == expected) return Status::Ok();
  return Status::Error(path + ": image is " + SizeText(size) + " but " +
                       (scan.camera_size.area() > 0 ? "camera_size in scan.yaml" : kTexture) +
                       " says " + SizeText(expected));
}

// An image of the scan at `path` (its texture, a light's, a frame) of the camera's size: judged by
// its header before a pixel is decoded when the size is known (scan.yaml's camera_size, or the
// texture read before it), and once decoded.
Status ReadScanImage(const std::string& path, const Scan& scan, int max_bits, cv::Mat* image) {
  const bool known = ExpectedSize(scan).area() > 0;
  Status s = ReadImageFile(path, image, max_bits, [&](cv::Size claimed) {
    return known ? CheckSize(path, claimed, scan) : Status::Ok();
  });
  if (s.ok()) s = CheckSize(path, image->size(), scan);
  return s;
}

Status MissingFrame(const std::string& path, int k, const Scan& scan) {
  return Status::Error(path + ": file is missing (frame " + std::to_string(k) + " of " +
                       std::to_string(scan.sequence.patterns.size()) + ", pattern '" +
                       Describe(scan.sequence.patterns[k]) + "')");
}

}  // namespace

Status ReadScanHeader(const std::string& dir, Scan* scan) {
  Status s = ReadScanYaml(dir, scan);
  if (!s.ok()) return s;
  const fs::path root(dir);
  // Judged by its header first when scan.yaml gives the camera's size.
  scan->texture.release();
  s = ReadScanImage((root / kTexture).string(), *scan, 16, &scan->texture);
  if (!s.ok()) return s;
  std::string why;
  if (!scan->leaf_hint.empty() &&
      !LeafHintFits(scan->leaf_hint, scan->texture.size(), OutlineOptions().max_view_share, &why)) {
    return Status::Error((root / kScanYaml).string() + ": key 'leaf_hint': " + why);
  }
  for (ScanLight& light : scan->lights) {
    const std::string path = (root / LightFileName(light.name)).string();
    if (!PathExists(path)) {
      return Status::Error(path + ": file is missing (light '" + light.name + "' of scan.yaml)");
    }
    s = ReadScanImage(path, *scan, 16, &light.image);
    if (!s.ok()) return s;
  }
  scan->frames.clear();
  // Every frame is there, an image, of the camera's size (a PNG's header says it without
  // decoding a pixel): a scan that cannot be decoded is refused before any work.
  const int n = static_cast<int>(scan->sequence.patterns.size());
  for (int k = 0; k < n; ++k) {
    const std::string path = (root / FrameName(k)).string();
    if (!PathExists(path)) return MissingFrame(path, k, *scan);
    cv::Size claimed;
    s = CheckImageHeader(path, &claimed);
    if (!s.ok()) return s;
    if (!claimed.empty()) s = CheckSize(path, claimed, *scan);
    if (!s.ok()) return s;
  }
  if (PathExists((root / FrameName(n)).string())) {
    return Status::Error((root / FrameName(n)).string() + ": more frames than the " +
                         std::to_string(n) + " patterns of scan.yaml");
  }
  scan->camera_size = ExpectedSize(*scan);
  return Status::Ok();
}

Status ReadFrames(const std::string& dir, const Scan& header, const FrameSink& take) {
  const fs::path root(dir);
  const int n = static_cast<int>(header.sequence.patterns.size());
  // PNG decoding dominates reading a scan: a few readers decode frames at once, each handing
  // its frame on as soon as it is read, so no more than one frame per reader is in memory.
  const int readers = std::clamp(cv::getNumberOfCPUs(), 1, std::min(n, 4));
  std::atomic<int> next{0};
  std::atomic<bool> stop{false};
  std::mutex take_mutex;
  std::vector<Status> errors(n, Status::Ok());
  auto read = [&] {
    for (int k = next++; k < n && !stop; k = next++) {
      const std::string path = (root / FrameName(k)).string();
      cv::Mat img;
      Status s =
          PathExists(path) ? ReadScanImage(path, header, 8, &img) : MissingFrame(path, k, header);
      if (s.ok()) {
        if (img.channels() == 3) cv::cvtColor(img, img, cv::COLOR_BGR2GRAY);
        const std::lock_guard<std::mutex> lock(take_mutex);
        if (!stop) s = take(k, img);
      }
      if (!s.ok()) {
        errors[k] = s;
        stop = true;  // Frames below k are all claimed: the lowest error is among those seen.
      }
    }
  };
  std::vector<std::thread> pool;
  for (int r = 1; r < readers; ++r) pool.emplace_back(read);
  read();
  for (std::thread& t : pool) t.join();
  for (const Status& e : errors) {
    if (!e.ok()) return e;
  }
  return Status::Ok();
}

Status ReadScan(const std::string& dir, Scan* scan) {
  Status s = ReadScanHeader(dir, scan);
  if (!s.ok()) return s;
  std::vector<cv::Mat> frames(scan->sequence.patterns.size());
  s = ReadFrames(dir, *scan, [&](int k, cv::Mat frame) {
    frames[k] = std::move(frame);
    return Status::Ok();
  });
  if (!s.ok()) return s;
  scan->frames = std::move(frames);
  return Status::Ok();
}

Status WriteScan(const std::string& dir, const Scan& scan) {
  Status s = MakeDirectories(dir);
  if (!s.ok()) return s;
  for (const ScanLight& light : scan.lights) {
    if (!ValidLightName(light.name)) {
      return Status::Error(dir + ": light name '" + light.name + "' is not a valid name");
    }
  }
  s = WriteScanYaml(dir, scan);
  if (!s.ok()) return s;
  const fs::path root(dir);
  s = WriteImage((root / kTexture).string(), scan.texture);
  if (!s.ok()) return s;
  for (const ScanLight& light : scan.lights) {
    s = WriteImage((root / LightFileName(light.name)).string(), light.image);
    if (!s.ok()) return s;
  }
  for (size_t k = 0; k < scan.frames.size(); ++k) {
    s = WriteFrameImage((root / FrameName(static_cast<int>(k))).string(), scan.frames[k]);
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Status WritePatterns(const std::string& dir, const PatternSequence& sequence) {
  Status s = MakeDirectories(dir);
  if (!s.ok()) return s;
  Scan header;
  header.sequence = sequence;
  s = WriteScanYaml(dir, header);
  if (!s.ok()) return s;
  for (size_t k = 0; k < sequence.patterns.size(); ++k) {
    s = WriteImage((fs::path(dir) / PatternName(static_cast<int>(k))).string(),
                   RenderPattern(sequence.patterns[k], sequence.projector_size));
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace vellum
