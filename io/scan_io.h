// Scan directories (docs/formats.md): scan.yaml (projector size, camera size, pattern sequence),
// texture.png, frame_000.png, ... with frame k taken while pattern k was shown.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"

namespace vellum {

std::string FrameName(int index);    // "frame_007.png"
std::string PatternName(int index);  // "pattern_007.png"

std::string LightFileName(const std::string& name);  // "light_raking-090.png"

// A scan the station gave up (recording failed, or parked after failing twice) holds the reason
// in raw/failed.txt (docs/formats.md).
inline constexpr const char* kGivenUpName = "failed.txt";
// Whether the scan whose raw folder is `raw_dir` was given up; the first line of its reason in
// *why (when asked).
bool ReadGivenUp(const std::string& raw_dir, std::string* why = nullptr);

// Reads scan.yaml only, into *header: the pattern sequence, the camera's size (0x0 when absent),
// the identity keys (shelfmark, folio, side, operator, note, label; any may be absent), sanitised
// (SanitizedIdentity); the extra lights (key `lights`: a sequence of {name, direction: [x, y,
// z]}, direction optional), names and directions only (the images are light_<name>.png); the
// operator's `leaf_hint: [x, y, width, height]` (camera pixels, within camera_size when that is
// given), empty when absent; what the object is (`object: leaf | book | auto`), auto when absent;
// where the live view saw the leaf run off the view (`live_off_view: [right, ...]`), none when
// absent. The texture and frames are not touched.
Status ReadScanYaml(const std::string& dir, Scan* header);
// Writes scan.yaml from *header's fields above; camera_size may be empty; identity keys only when
// set; `lights` by name and direction; leaf_hint when not empty; object when not auto;
// live_off_view when any side.
Status WriteScanYaml(const std::string& dir, const Scan& header);

// A station's extra lights, as vellum-projector and vellum-lights read them from one
// YAML file: `lights`, a sequence of {name, direction: [x, y, z], channel} (direction optional, as
// in scan.yaml; channel: the light's switch on a relay board, 0 to 255, optional), and
// `studio_channel` (optional): the studio lamps' switch, off while an extra light is on.
struct StationLights {
  std::vector<ScanLight> lights;  // Names and directions; no images.
  std::vector<int> channels;      // One per light, -1 when not given.
  int studio_channel = -1;
};
Status ReadLightsFile(const std::string& path, StationLights* out);

// Reads scan.yaml, texture.png and the lights' images, and checks that every frame file is there,
// an image, of the camera's size (from its PNG header, no pixel decoded); scan->frames is left
// empty. Errors name the file and the problem.
Status ReadScanHeader(const std::string& dir, Scan* scan);
// Hands on one frame as it is read: its index and its 8-bit one-channel image.
using FrameSink = std::function<Status(int index, cv::Mat frame)>;
// Reads the frames of a scan (its header from ReadScanHeader) with a few readers at once, handing
// each to `take` as soon as it is read: one call at a time, in no set order, so no more frames
// are in memory than readers. Stops at the first error, a frame's or take's; the one returned
// is the lowest-numbered frame's, as a serial read would give.
Status ReadFrames(const std::string& dir, const Scan& header, const FrameSink& take);
// Reads and validates a whole scan directory (ReadScanHeader, then every frame).
Status ReadScan(const std::string& dir, Scan* scan);
// Reads the scan directory's texture.png alone.
Status ReadTexture(const std::string& dir, cv::Mat* texture);
// Writes scan.yaml, texture.png, the lights' images and the frames (creating the directory).
Status WriteScan(const std::string& dir, const Scan& scan);
// Writes the projector images pattern_000.png, ... and scan.yaml (no camera size).
Status WritePatterns(const std::string& dir, const PatternSequence& sequence);

// Writes a structured-light frame (8-bit, one channel) as a PNG without row filters or
// deflate: at 24 MP 60 ms against 280 ms for OpenCV's default PNG (bench/archive_bench), so
// recording keeps up with a 5 fps camera; the file is the frame's own size (1.8 times the
// default PNG's). Any PNG reader reads it; errors name the file.
Status WriteFrameImage(const std::string& path, const cv::Mat& frame);
Status MakeDirectories(const std::string& dir);
// Whether `path` exists; an error looking (a folder an operator made unreadable) counts as no,
// never as an exception on a daemon's thread.
bool PathExists(const std::string& path);

}  // namespace vellum
