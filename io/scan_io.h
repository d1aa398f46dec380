// Scan directories (DESIGN.md): scan.yaml (projector size, camera size, pattern sequence),
// texture.png, frame_000.png, ... with frame k taken while pattern k was shown.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"

namespace vellum {

std::string FrameName(int index);    // "frame_007.png"
std::string PatternName(int index);  // "pattern_007.png"

// Reads scan.yaml only; its identity keys (shelfmark, folio, side, operator, note, label; any may
// be absent) into *identity when given, sanitised (SanitizedIdentity).
Status ReadScanYaml(const std::string& dir, PatternSequence* sequence, cv::Size* camera_size,
                    ScanIdentity* identity = nullptr);
// Writes scan.yaml; camera_size may be empty; identity keys only when set.
Status WriteScanYaml(const std::string& dir, const PatternSequence& sequence, cv::Size camera_size,
                     const ScanIdentity& identity = ScanIdentity());

// Reads and validates a whole scan directory; errors name the file and the problem.
Status ReadScan(const std::string& dir, Scan* scan);
// Reads the scan directory's texture.png alone.
Status ReadTexture(const std::string& dir, cv::Mat* texture);
// Writes scan.yaml, texture.png and the frames (creating the directory).
Status WriteScan(const std::string& dir, const Scan& scan);
// Writes the projector images pattern_000.png, ... and scan.yaml (no camera size).
Status WritePatterns(const std::string& dir, const PatternSequence& sequence);

// Writes an image, creating nothing; errors name the file.
Status WriteImage(const std::string& path, const cv::Mat& image);
Status MakeDirectories(const std::string& dir);
// Whether `path` exists; an error looking (a folder an operator made unreadable) counts as no,
// never as an exception on a daemon's thread.
bool PathExists(const std::string& path);

}  // namespace vellum
