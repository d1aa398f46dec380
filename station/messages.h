// Conversions between the bus's messages (lcmtypes/) and the core's types, with validation:
// a message from the bus is untrusted, so every reader checks sizes, ranges and NaNs and
// returns a Status naming what was wrong. Large products travel in row chunks.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/calibration.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"
#include "pipeline/context.h"
#include "pipeline/report.h"
#include "station/chunks.h"
#include "station/clock.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/correspondence_t.hpp"
#include "vellum/image_t.hpp"
#include "vellum/light_spec_t.hpp"
#include "vellum/mesh_t.hpp"
#include "vellum/pattern_spec_t.hpp"
#include "vellum/point_cloud_t.hpp"
#include "vellum/scan_context_t.hpp"
#include "vellum/scan_identity_t.hpp"
#include "vellum/scan_started_t.hpp"
#include "vellum/stage_report_t.hpp"
#include "vellum/texture_t.hpp"

namespace vellum::station {

// Messages stay under this size on the bus (LCM udpm loses a whole message with any of its
// fragments; smaller messages lose less and reassemble within the receive buffer).
inline constexpr size_t kMaxMessageBytes = 1 << 20;
// The most pixels a product of a camera's view may claim (its rows and columns as a message
// gives them, or a page mask's): 2^28, 268 M, above a 150 MP back. A bad or hostile message that
// claims more is refused before anything that size is allocated.
inline constexpr int64_t kMaxViewPixels = int64_t{1} << 28;

// Images: gray or BGR, 8 bits a sample (GREY, BGR3) or 16 (Y16, BGR6: a deeper camera's texture
// and lights).
void ToMessage(const cv::Mat& image, image_t* msg);
Status FromMessage(const image_t& msg, cv::Mat* image);  // A deep copy.

pattern_spec_t ToMessage(const PatternSpec& spec);
// A scan's identity on the bus and back (FromMessage sanitises: SanitizedIdentity).
scan_identity_t ToMessage(const ScanIdentity& identity);
ScanIdentity FromMessage(const scan_identity_t& msg);
// A scan's context as it travels with its products, and back (checked: the hint a rectangle, the
// object known, the checksum a SHA-256; the identity sanitised).
scan_context_t ToMessage(const ScanContext& context);
Status FromMessage(const scan_context_t& msg, ScanContext* context);
// The leaf hint of SCAN_REQUEST and SCAN_STARTED (x, y, width, height as fractions of the
// camera's view) and back. In camera pixels of a view of `camera` pixels, within it; empty when
// the message has none (width 0) or it is not a region of the view (NaN, outside 0 .. 1).
cv::Rect LeafHintPixels(const float hint[4], cv::Size camera);
void ToLeafHint(const cv::Rect2d& fraction, float hint[4]);
// What SCAN_STARTED says of a scan beyond its patterns: its identity and the leaf hint (in
// pixels of scan->camera_size, which must be known).
void FromStarted(const scan_started_t& msg, Scan* scan);
Status FromMessage(const pattern_spec_t& msg, PatternSpec* spec);

// An extra light of a scan (its name and direction; its image travels as the capture's). The
// reader checks the name (ValidLightName) and a direction (UnitLightDirection; made unit).
light_spec_t ToMessage(const ScanLight& light);
Status FromMessage(const light_spec_t& msg, ScanLight* light);

void ToMessage(const Calibration& calibration, calibration_t* msg);
Status FromMessage(const calibration_t& msg, Calibration* calibration);

// Row ranges [begin, begin + count) that split `rows` rows of `bytes_per_row` bytes into
// chunks of at most max_bytes (at least one row each).
std::vector<std::pair<int, int>> RowChunks(int rows, size_t bytes_per_row,
                                           size_t max_bytes = kMaxMessageBytes);

// Which chunks of one scan's product have arrived.
class ChunkSet {
 public:
  // Starts on the first chunk; later chunks must agree on the count. Duplicates are errors.
  // `now`: when it came (the receiving node's clock).
  Status Add(int64_t scan_id, int index, int count, Clock::time_point now);
  bool Started() const { return count_ > 0; }
  // Started, incomplete, and no chunk for longer than `seconds` before `now`.
  bool Stale(double seconds, Clock::time_point now) const;
  bool Complete() const { return Started() && received_ == count_; }
  int64_t scan_id() const { return scan_id_; }
  // Whether chunk `index` of this scan came already.
  bool Has(int64_t scan_id, int index) const {
    return Started() && scan_id == scan_id_ && index >= 0 && index < count_ && have_[index];
  }
  // "chunks 3, 5 of 12 missing".
  std::string Missing() const;
  std::vector<int32_t> MissingIndices() const;
  int received() const { return received_; }
  void Reset() { *this = ChunkSet(); }

 private:
  int64_t scan_id_ = 0;
  int count_ = 0, received_ = 0;
  std::vector<bool> have_;
  Clock::time_point last_add_;
};

// A stage's report as it travels with the products (only the reports of stages that
// succeeded travel); the reader checks that every value has a section and a key.
stage_report_t ToMessage(const StageReport& report);
Status FromMessage(const stage_report_t& msg, StageReport* report);
// The reports a product carries (every chunk carries them all).
Status FromMessages(const std::vector<stage_report_t>& msgs, std::vector<StageReport>* reports);

// The texture in chunks of rows (TEXTURE; the scan has `light_count` extra lights), or with
// `light` an extra light's image (LIGHT_TEXTURE), 8 or 16 bits a sample, and its reassembly.
std::vector<texture_t> TextureMessages(int64_t scan_id, const cv::Mat& texture, int light_count = 0,
                                       const ScanLight* light = nullptr);
Status AddChunk(const texture_t& msg, cv::Mat* texture);

// Decoded correspondences: chunks of rows, and their reassembly. A reassembled map has an ok
// status (it decoded upstream) and the decoder's count of lit pixels. Every chunk carries the
// scan's context and the reports of its stages so far.
ChunkMaker<correspondence_t> CorrespondenceChunks(int64_t scan_id, const DecodeResult& decoded,
                                                  cv::Size projector_size,
                                                  const ScanContext& context,
                                                  const std::vector<StageReport>& stages);
// The same chunks, all at once.
std::vector<correspondence_t> ToMessages(int64_t scan_id, const DecodeResult& decoded,
                                         cv::Size projector_size, const ScanContext& context,
                                         const std::vector<StageReport>& stages);
// Checks a chunk against the map under construction (allocated on the first chunk) and copies
// its rows into it.
Status AddChunk(const correspondence_t& msg, DecodeResult* decoded, cv::Size* projector_size);

// The point map, with the decoder's amplitude (for the albedo) when it is of its size.
ChunkMaker<point_cloud_t> PointCloudChunks(int64_t scan_id, const cv::Mat& points,
                                           const cv::Mat& amplitude, const ScanContext& context,
                                           const std::vector<StageReport>& stages);
// The same chunks, all at once.
std::vector<point_cloud_t> ToMessages(int64_t scan_id, const cv::Mat& points,
                                      const cv::Mat& amplitude, const ScanContext& context,
                                      const std::vector<StageReport>& stages);
// Copies a chunk's rows into *points and, given `amplitude`, its amplitude (left empty when
// the product came without).
Status AddChunk(const point_cloud_t& msg, cv::Mat* points, cv::Mat* amplitude = nullptr);

// Which page of its scan a sheet is, and the page's mask (CV_8U, camera pixels).
struct SheetPage {
  std::string name;  // "" for a single leaf; "left", "right" on a spread.
  int index = 0, count = 1;
  cv::Mat mask;
};

// The flattened sheet of one page as nodes (kind, point, flat), with the page's mask as runs;
// the receiver rebuilds springs and quads with ConnectSheet.
// The flattening's figures (its strains) travel with the sheet.
std::vector<mesh_t> ToMessages(int64_t scan_id, const Mesh& mesh, bool bend_springs,
                               const FlattenResult& flat, const ScanContext& context,
                               const std::vector<StageReport>& stages, const SheetPage& page);
// The springs' rest lengths as a sheet's chunks carried them (each chunk those of the springs
// whose first node lies in its rows), by the chunk's first row: measured along the surface
// (MeshOptions::rest_along_surface), they are not the nodes' straight distances that
// ConnectSheet gives the springs it rebuilds.
struct SheetRests {
  std::map<int, std::vector<double>> by_first_row;
};
// Copies a chunk's nodes into *mesh (cols, rows, kind, point) and *flat (its flat positions and
// strains; status ok), its page (the mask from chunk 0) into *page, and its springs' rest
// lengths into *rests.
Status AddChunk(const mesh_t& msg, Mesh* mesh, FlattenResult* flat, SheetPage* page,
                SheetRests* rests = nullptr);
// Sets the rest lengths of the springs ConnectSheet rebuilt (mesh->springs, in its order) to
// those the sheet's chunks carried; an error when they do not number the springs.
Status SetRestLengths(const SheetRests& rests, Mesh* mesh);

}  // namespace vellum::station
