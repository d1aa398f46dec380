#include "station/messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/common/text.h"

// 16-bit samples (a deep camera's texture) go on the bus as the host holds them: little-endian,
// as image_t and texture_t say.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "the bus's 16-bit samples are little-endian");

namespace vellum::station {
namespace {

template <class Matx>
void CopyOut(const Matx& m, double* out) {
  for (int k = 0; k < Matx::rows * Matx::cols; ++k) out[k] = m.val[k];
}

void ToModel(const CameraModel& c, camera_model_t* m) {
  m->width = c.size.width;
  m->height = c.size.height;
  CopyOut(c.matrix, m->matrix);
  CopyOut(c.distortion, m->distortion);
  CopyOut(c.rotation, m->rotation);
  CopyOut(c.translation, m->translation);
}

bool AllFinite(const double* v, int n) {
  for (int k = 0; k < n; ++k) {
    if (!std::isfinite(v[k])) return false;
  }
  return true;
}

Status FromModel(const camera_model_t& m, const std::string& what, CameraModel* c) {
  if (!AllFinite(m.matrix, 9) || !AllFinite(m.distortion, 5) || !AllFinite(m.rotation, 9) ||
      !AllFinite(m.translation, 3)) {
    return Status::Error(what + ": not all numbers are finite");
  }
  c->size = cv::Size(m.width, m.height);
  std::copy(m.matrix, m.matrix + 9, c->matrix.val);
  std::copy(m.distortion, m.distortion + 5, c->distortion.val);
  std::copy(m.rotation, m.rotation + 9, c->rotation.val);
  std::copy(m.translation, m.translation + 3, c->translation.val);
  std::string why;
  if (!c->Check(&why)) return Status::Error(what + ": " + why);
  return Status::Ok();
}

// Checks a row chunk's geometry against the whole product's.
Status CheckRows(const std::string& what, int width, int height, int row_begin, int row_count,
                 int n, int index, int count) {
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535 ||
      static_cast<int64_t>(width) * height > kMaxViewPixels) {
    return Status::Error(what + ": bad size " + std::to_string(width) + "x" +
                         std::to_string(height));
  }
  if (row_begin < 0 || row_count <= 0 || row_count > height - row_begin) {
    return Status::Error(what + ": rows " + std::to_string(row_begin) + "+" +
                         std::to_string(row_count) + " outside the " + std::to_string(height) +
                         "-row image");
  }
  if (static_cast<int64_t>(n) != static_cast<int64_t>(row_count) * width) {
    return Status::Error(what + ": " + std::to_string(n) + " values for " +
                         std::to_string(row_count) + " rows of " + std::to_string(width));
  }
  if (count <= 0 || index < 0 || index >= count) {
    return Status::Error(what + ": chunk " + std::to_string(index) + " of " +
                         std::to_string(count));
  }
  return Status::Ok();
}

// Every chunk of a product carries the reports of the stages so far.
template <class Msg>
void SetStages(const std::vector<StageReport>& stages, Msg* m) {
  m->stages.clear();
  for (const StageReport& s : stages) m->stages.push_back(ToMessage(s));
  m->nstages = static_cast<int32_t>(m->stages.size());
}

}  // namespace

void ToMessage(const cv::Mat& image, image_t* msg) {
  CV_Assert((image.depth() == CV_8U || image.depth() == CV_16U) &&
            (image.channels() == 1 || image.channels() == 3));
  const bool deep = image.depth() == CV_16U;
  msg->width = image.cols;
  msg->height = image.rows;
  msg->row_stride = static_cast<int32_t>(image.cols * image.elemSize());
  if (image.channels() == 1) {
    msg->pixelformat =
        deep ? int32_t{image_t::PIXEL_FORMAT_GRAY16} : int32_t{image_t::PIXEL_FORMAT_GRAY};
  } else {
    msg->pixelformat =
        deep ? int32_t{image_t::PIXEL_FORMAT_BGR48} : int32_t{image_t::PIXEL_FORMAT_BGR};
  }
  msg->size = msg->row_stride * image.rows;
  msg->data.resize(msg->size);
  for (int y = 0; y < image.rows; ++y) {
    std::memcpy(msg->data.data() + static_cast<size_t>(y) * msg->row_stride, image.ptr(y),
                msg->row_stride);
  }
}

Status FromMessage(const image_t& msg, cv::Mat* image) {
  int channels = 0, depth = CV_8U;
  switch (msg.pixelformat) {
    case image_t::PIXEL_FORMAT_GRAY:
      channels = 1;
      break;
    case image_t::PIXEL_FORMAT_BGR:
      channels = 3;
      break;
    case image_t::PIXEL_FORMAT_GRAY16:
      channels = 1, depth = CV_16U;
      break;
    case image_t::PIXEL_FORMAT_BGR48:
      channels = 3, depth = CV_16U;
      break;
    default: {
      char fourcc[5] = {0};
      for (int k = 0; k < 4; ++k) {
        const char c = static_cast<char>((msg.pixelformat >> (8 * k)) & 0xff);
        fourcc[k] = c >= 32 && c < 127 ? c : '?';
      }
      return Status::Error(std::string("image pixel format '") + fourcc +
                           "' is not supported (GREY, BGR3, Y16 or BGR6)");
    }
  }
  if (msg.width <= 0 || msg.height <= 0 || msg.width > 65535 || msg.height > 65535) {
    return Status::Error("image size " + std::to_string(msg.width) + "x" +
                         std::to_string(msg.height) + " is not valid");
  }
  const int64_t row_bytes = static_cast<int64_t>(msg.width) * channels * (depth == CV_16U ? 2 : 1);
  if (msg.row_stride < row_bytes) {
    return Status::Error("image row_stride " + std::to_string(msg.row_stride) +
                         " is less than a row of " + std::to_string(row_bytes) + " bytes");
  }
  const int64_t need = static_cast<int64_t>(msg.row_stride) * (msg.height - 1) + row_bytes;
  if (msg.size < need || static_cast<int64_t>(msg.data.size()) != msg.size) {
    return Status::Error("image data is " + std::to_string(msg.data.size()) + " bytes; " +
                         std::to_string(msg.width) + "x" + std::to_string(msg.height) + " needs " +
                         std::to_string(need));
  }
  image->create(msg.height, msg.width, CV_MAKETYPE(depth, channels));
  for (int y = 0; y < msg.height; ++y) {
    std::memcpy(image->ptr(y), msg.data.data() + static_cast<size_t>(y) * msg.row_stride,
                row_bytes);
  }
  return Status::Ok();
}

pattern_spec_t ToMessage(const PatternSpec& spec) {
  pattern_spec_t m;
  m.kind = static_cast<int8_t>(spec.kind);
  m.axis = static_cast<int8_t>(spec.axis);
  m.bit = static_cast<int8_t>(spec.bit);
  m.inverted = spec.inverted;
  m.step = static_cast<int16_t>(spec.step);
  m.steps = static_cast<int16_t>(spec.steps);
  m.period_px = static_cast<int16_t>(spec.period_px);
  return m;
}

light_spec_t ToMessage(const ScanLight& light) {
  light_spec_t m{};
  m.name = light.name;
  m.directed = light.directed();
  for (int i = 0; i < 3; ++i) m.direction[i] = light.direction[i];
  return m;
}

Status FromMessage(const light_spec_t& m, ScanLight* light) {
  *light = ScanLight();
  if (!ValidLightName(m.name)) {
    return Status::Error("light name '" + Printable(m.name, 40) +
                         "' is not 1 to 32 of a-z, 0-9, '-' and '_'");
  }
  light->name = m.name;
  if (m.directed && !UnitLightDirection(cv::Vec3d(m.direction[0], m.direction[1], m.direction[2]),
                                        &light->direction)) {
    return Status::Error("light '" + m.name + "': its direction must point up from the table");
  }
  return Status::Ok();
}

Status FromMessage(const pattern_spec_t& m, PatternSpec* spec) {
  if (m.kind < pattern_spec_t::KIND_WHITE || m.kind > pattern_spec_t::KIND_PHASE) {
    return Status::Error("pattern kind " + std::to_string(m.kind) + " is not known");
  }
  if (m.axis != pattern_spec_t::AXIS_COLUMN && m.axis != pattern_spec_t::AXIS_ROW) {
    return Status::Error("pattern axis " + std::to_string(m.axis) + " is not known");
  }
  PatternSpec s;
  s.kind = static_cast<PatternKind>(m.kind);
  if (s.kind == PatternKind::kGray || s.kind == PatternKind::kPhase) {
    s.axis = static_cast<Axis>(m.axis);
  }
  if (s.kind == PatternKind::kGray) {
    if (m.bit < 0 || m.bit > 20) return Status::Error("gray pattern bit out of range");
    s.bit = m.bit;
    s.inverted = m.inverted;
  } else if (s.kind == PatternKind::kPhase) {
    if (m.steps < 3 || m.step < 0 || m.step >= m.steps || m.period_px < 4) {
      return Status::Error("phase pattern step/steps/period out of range");
    }
    s.step = m.step;
    s.steps = m.steps;
    s.period_px = m.period_px;
  }
  *spec = s;
  return Status::Ok();
}

scan_identity_t ToMessage(const ScanIdentity& id) {
  scan_identity_t m;
  m.label = id.label;
  m.shelfmark = id.shelfmark;
  m.folio = id.folio;
  m.side = id.side;
  m.operator_name = id.operator_name;
  m.note = id.note;
  return m;
}

ScanIdentity FromMessage(const scan_identity_t& m) {
  ScanIdentity id;
  id.label = m.label;
  id.shelfmark = m.shelfmark;
  id.folio = m.folio;
  id.side = m.side;
  id.operator_name = m.operator_name;
  id.note = m.note;
  return SanitizedIdentity(id);
}

scan_context_t ToMessage(const ScanContext& context) {
  scan_context_t m;
  m.identity = ToMessage(context.identity);
  const cv::Rect& hint = context.leaf_hint;
  const bool has_hint = !hint.empty();
  m.leaf_hint[0] = has_hint ? hint.x : 0;
  m.leaf_hint[1] = has_hint ? hint.y : 0;
  m.leaf_hint[2] = has_hint ? hint.width : 0;
  m.leaf_hint[3] = has_hint ? hint.height : 0;
  m.object = ToString(context.object);
  m.live_off_view = ViewSidesText(context.live_off_view);
  m.calibration_sha256 = context.calibration_sha256;
  m.scale_error_percent = context.scale_error_percent;
  return m;
}

Status FromMessage(const scan_context_t& m, ScanContext* context) {
  ScanContext c;
  c.identity = FromMessage(m.identity);
  const int32_t* h = m.leaf_hint;
  if (h[2] != 0 || h[3] != 0) {
    if (h[0] < 0 || h[1] < 0 || h[2] <= 0 || h[3] <= 0 || h[2] > 65535 || h[3] > 65535) {
      return Status::Error("scan context: leaf hint " + std::to_string(h[0]) + "," +
                           std::to_string(h[1]) + "," + std::to_string(h[2]) + "," +
                           std::to_string(h[3]) + " is not a rectangle of camera pixels");
    }
    c.leaf_hint = cv::Rect(h[0], h[1], h[2], h[3]);
  }
  if (!ParseObjectKind(m.object, &c.object)) {
    return Status::Error("scan context: unknown object '" + m.object + "'");
  }
  if (!ParseViewSides(m.live_off_view, &c.live_off_view)) {
    return Status::Error("scan context: live_off_view '" + Printable(m.live_off_view, 40) +
                         "' is not the view's sides");
  }
  const std::string& sha = m.calibration_sha256;
  if (!sha.empty() &&
      (sha.size() != 64 || sha.find_first_not_of("0123456789abcdef") != std::string::npos)) {
    return Status::Error("scan context: calibration_sha256 '" + sha + "' is not a SHA-256 in hex");
  }
  c.calibration_sha256 = sha;
  if (std::isinf(m.scale_error_percent)) {
    return Status::Error("scan context: the scale error is infinite");
  }
  c.scale_error_percent = m.scale_error_percent;
  *context = c;
  return Status::Ok();
}

cv::Rect LeafHintPixels(const float hint[4], cv::Size camera) {
  const float x = hint[0], y = hint[1], w = hint[2], h = hint[3];
  // Written as they are so that NaN fails each test.
  if (!(x >= 0 && y >= 0 && w > 0 && h > 0 && x + w <= 1.0001f && y + h <= 1.0001f)) {
    return cv::Rect();
  }
  // A whole pixel's region goes there and back exactly (float's rounding forgiven).
  constexpr double kSlack = 1e-3;
  const cv::Rect r(
      cv::Point(cvFloor(x * camera.width + kSlack), cvFloor(y * camera.height + kSlack)),
      cv::Point(cvCeil((x + w) * camera.width - kSlack), cvCeil((y + h) * camera.height - kSlack)));
  return r & cv::Rect(cv::Point(0, 0), camera);
}

void FromStarted(const scan_started_t& m, Scan* scan) {
  scan->identity = FromMessage(m.identity);
  scan->leaf_hint = LeafHintPixels(m.leaf_hint, scan->camera_size);
  scan->object = ObjectKind::kAuto;
  if (!m.object.empty()) ParseObjectKind(m.object, &scan->object);  // ScanGate refuses others.
  scan->live_off_view = 0;
  ParseViewSides(m.live_off_view, &scan->live_off_view);  // ScanGate refuses others.
}

void ToLeafHint(const cv::Rect2d& fraction, float hint[4]) {
  hint[0] = static_cast<float>(fraction.x);
  hint[1] = static_cast<float>(fraction.y);
  hint[2] = static_cast<float>(fraction.width);
  hint[3] = static_cast<float>(fraction.height);
}

void ToMessage(const Calibration& calibration, calibration_t* msg) {
  ToModel(calibration.camera, &msg->camera);
  ToModel(calibration.projector, &msg->projector);
  msg->min_z_mm = calibration.min_z_mm;
  msg->max_z_mm = calibration.max_z_mm;
  msg->scale_error_percent = calibration.scale_error_percent;
}

Status FromMessage(const calibration_t& msg, Calibration* calibration) {
  Calibration c;
  Status s = FromModel(msg.camera, "calibration camera", &c.camera);
  if (!s.ok()) return s;
  s = FromModel(msg.projector, "calibration projector", &c.projector);
  if (!s.ok()) return s;
  if (!std::isfinite(msg.min_z_mm) || !std::isfinite(msg.max_z_mm) ||
      !(msg.min_z_mm < msg.max_z_mm)) {
    return Status::Error("calibration: the working volume must be finite heights, low < high");
  }
  if (!std::isnan(msg.scale_error_percent) &&
      !(msg.scale_error_percent >= 0 && std::isfinite(msg.scale_error_percent))) {
    return Status::Error("calibration: scale_error_percent must be >= 0 or NaN (not measured)");
  }
  c.min_z_mm = msg.min_z_mm;
  c.max_z_mm = msg.max_z_mm;
  c.scale_error_percent = msg.scale_error_percent;
  *calibration = c;
  return Status::Ok();
}

std::vector<std::pair<int, int>> RowChunks(int rows, size_t bytes_per_row, size_t max_bytes) {
  const int per =
      static_cast<int>(std::max<size_t>(1, max_bytes / std::max<size_t>(1, bytes_per_row)));
  std::vector<std::pair<int, int>> chunks;
  for (int begin = 0; begin < rows; begin += per)
    chunks.emplace_back(begin, std::min(per, rows - begin));
  return chunks;
}

Status ChunkSet::Add(int64_t scan_id, int index, int count, Clock::time_point now) {
  if (count <= 0 || index < 0 || index >= count) {
    return Status::Error("chunk " + std::to_string(index) + " of " + std::to_string(count) +
                         " is not a valid chunk number");
  }
  if (!Started()) {
    scan_id_ = scan_id;
    count_ = count;
    have_.assign(count, false);
  } else if (scan_id != scan_id_ || count != count_) {
    return Status::Error("chunk " + std::to_string(index) + " of " + std::to_string(count) +
                         " does not belong to scan " + std::to_string(scan_id_) + "'s " +
                         std::to_string(count_) + " chunks");
  }
  if (have_[index]) return Status::Error("chunk " + std::to_string(index) + " came twice");
  last_add_ = now;
  have_[index] = true;
  ++received_;
  return Status::Ok();
}

bool ChunkSet::Stale(double seconds, Clock::time_point now) const {
  return Started() && !Complete() && now - last_add_ > Seconds(seconds);
}

std::string ChunkSet::Missing() const {
  std::string list;
  int n = 0;
  for (int k = 0; k < count_; ++k) {
    if (have_[k]) continue;
    if (n < 8) list += (n ? ", " : "") + std::to_string(k);
    ++n;
  }
  if (n > 8) list += ", ...";
  return "chunk" + std::string(n == 1 ? " " : "s ") + list + " of " + std::to_string(count_) +
         " missing";
}

std::vector<int32_t> ChunkSet::MissingIndices() const {
  std::vector<int32_t> missing;
  for (int k = 0; k < count_; ++k) {
    if (!have_[k]) missing.push_back(k);
  }
  return missing;
}

stage_report_t ToMessage(const StageReport& report) {
  stage_report_t m;
  m.stage = report.stage;
  m.page = report.page;
  m.seconds = report.seconds;
  for (const ReportValue& v : report.values) {
    m.sections.push_back(v.section);
    m.keys.push_back(v.key);
    m.is_text.push_back(v.is_text);
    m.texts.push_back(v.text);
    m.numbers.push_back(v.number);
  }
  m.nvalues = static_cast<int32_t>(m.keys.size());
  m.outputs = report.outputs;
  m.noutputs = static_cast<int32_t>(m.outputs.size());
  for (const Warning& w : report.warnings) {
    m.warning_codes.push_back(w.code);
    m.warning_messages.push_back(w.message);
  }
  m.nwarnings = static_cast<int32_t>(m.warning_codes.size());
  return m;
}

Status FromMessage(const stage_report_t& m, StageReport* report) {
  StageReport r;
  if (m.stage.empty()) return Status::Error("a stage report without a stage name");
  if (!std::isfinite(m.seconds) || m.seconds < 0) {
    return Status::Error("stage report " + m.stage + ": bad time");
  }
  r.stage = m.stage;
  r.page = m.page;
  r.seconds = m.seconds;
  for (int k = 0; k < m.nvalues; ++k) {
    if (m.sections[k].empty() || m.keys[k].empty()) {
      return Status::Error("stage report " + m.stage + ": value " + std::to_string(k) +
                           " has no section or key");
    }
    ReportValue v;
    v.section = m.sections[k];
    v.key = m.keys[k];
    v.is_text = m.is_text[k];
    v.text = m.texts[k];
    v.number = m.numbers[k];
    r.values.push_back(std::move(v));
  }
  r.outputs = m.outputs;
  for (int k = 0; k < m.nwarnings; ++k) {
    if (m.warning_codes[k].empty()) {
      return Status::Error("stage report " + m.stage + ": a warning without a code");
    }
    r.warnings.push_back({m.warning_codes[k], m.warning_messages[k]});
  }
  r.status = Status::Ok();
  *report = std::move(r);
  return Status::Ok();
}

Status FromMessages(const std::vector<stage_report_t>& msgs, std::vector<StageReport>* reports) {
  std::vector<StageReport> out(msgs.size());
  for (size_t k = 0; k < msgs.size(); ++k) {
    const Status s = FromMessage(msgs[k], &out[k]);
    if (!s.ok()) return s;
  }
  *reports = std::move(out);
  return Status::Ok();
}

std::vector<texture_t> TextureMessages(int64_t scan_id, const cv::Mat& texture, int light_count,
                                       const ScanLight* light) {
  CV_Assert((texture.depth() == CV_8U || texture.depth() == CV_16U) &&
            (texture.channels() == 1 || texture.channels() == 3));
  const size_t row_bytes = texture.cols * texture.elemSize();
  const auto chunks = RowChunks(texture.rows, row_bytes);
  std::vector<texture_t> out(chunks.size());
  for (size_t c = 0; c < chunks.size(); ++c) {
    texture_t& m = out[c];
    m.utime = 0;
    m.scan_id = scan_id;
    m.chunk_index = static_cast<int32_t>(c);
    m.chunk_count = static_cast<int32_t>(chunks.size());
    m.width = texture.cols;
    m.height = texture.rows;
    m.row_begin = chunks[c].first;
    m.row_count = chunks[c].second;
    m.channels = texture.channels();
    m.bits = texture.depth() == CV_16U ? 16 : 8;
    m.light_count = light_count;
    if (light) m.light = ToMessage(*light);
    m.size = static_cast<int32_t>(m.row_count * row_bytes);
    m.data.resize(m.size);
    for (int r = 0; r < m.row_count; ++r) {
      std::memcpy(&m.data[r * row_bytes], texture.ptr(m.row_begin + r), row_bytes);
    }
  }
  return out;
}

Status AddChunk(const texture_t& m, cv::Mat* texture) {
  if (m.channels != 1 && m.channels != 3) {
    return Status::Error("TEXTURE: " + std::to_string(m.channels) + " channels (1 or 3)");
  }
  if (m.bits != 8 && m.bits != 16) {
    return Status::Error("TEXTURE: " + std::to_string(m.bits) + " bits a sample (8 or 16)");
  }
  const int pixel_bytes = m.channels * m.bits / 8;
  if (m.size % pixel_bytes != 0) return Status::Error("TEXTURE: size is not whole pixels");
  Status s = CheckRows("TEXTURE", m.width, m.height, m.row_begin, m.row_count, m.size / pixel_bytes,
                       m.chunk_index, m.chunk_count);
  if (!s.ok()) return s;
  const cv::Size size(m.width, m.height);
  const int type = CV_MAKETYPE(m.bits == 16 ? CV_16U : CV_8U, m.channels);
  if (texture->empty()) {
    texture->create(size, type);
  } else if (texture->size() != size || texture->type() != type) {
    return Status::Error("TEXTURE: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on the size, channels or bits");
  }
  const size_t row_bytes = static_cast<size_t>(m.width) * pixel_bytes;
  for (int r = 0; r < m.row_count; ++r) {
    std::memcpy(texture->ptr(m.row_begin + r), &m.data[r * row_bytes], row_bytes);
  }
  return Status::Ok();
}

ChunkMaker<correspondence_t> CorrespondenceChunks(int64_t scan_id, const DecodeResult& decoded,
                                                  cv::Size projector_size,
                                                  const ScanContext& context,
                                                  const std::vector<StageReport>& stages) {
  const int width = decoded.projector_x.cols, height = decoded.projector_x.rows;
  const bool amplitude = decoded.amplitude.size() == decoded.projector_x.size();
  const auto chunks = RowChunks(height, static_cast<size_t>(width) * (amplitude ? 13 : 9));
  ChunkMaker<correspondence_t> maker;
  maker.count = static_cast<int>(chunks.size());
  // Its maps' headers (their pixels shared, not copied) and the rest by value.
  maker.make = [scan_id, decoded, projector_size, context_message = ToMessage(context), stages,
                chunks, amplitude, width, height](int c, correspondence_t* out) {
    correspondence_t& m = *out;
    m.utime = 0;
    m.scan_id = scan_id;
    m.chunk_index = c;
    m.chunk_count = static_cast<int32_t>(chunks.size());
    m.width = width;
    m.height = height;
    m.row_begin = chunks[static_cast<size_t>(c)].first;
    m.row_count = chunks[static_cast<size_t>(c)].second;
    m.projector_width = projector_size.width;
    m.projector_height = projector_size.height;
    m.has_columns = decoded.has_columns;
    m.has_rows = decoded.has_rows;
    m.n = m.row_count * width;
    m.projector_x.resize(m.n);
    m.projector_y.resize(m.n);
    m.valid.resize(m.n);
    for (int r = 0; r < m.row_count; ++r) {
      const int y = m.row_begin + r;
      std::memcpy(&m.projector_x[r * width], decoded.projector_x.ptr<float>(y), width * 4);
      std::memcpy(&m.projector_y[r * width], decoded.projector_y.ptr<float>(y), width * 4);
      std::memcpy(&m.valid[r * width], decoded.valid.ptr<uint8_t>(y), width);
    }
    m.amplitude.resize(amplitude ? m.n : 0);
    for (int r = 0; amplitude && r < m.row_count; ++r) {
      std::memcpy(&m.amplitude[r * width], decoded.amplitude.ptr<float>(m.row_begin + r),
                  width * 4);
    }
    m.namplitude = static_cast<int32_t>(m.amplitude.size());
    m.lit = decoded.stats.lit;
    m.context = context_message;
    SetStages(stages, &m);
  };
  return maker;
}

std::vector<correspondence_t> ToMessages(int64_t scan_id, const DecodeResult& decoded,
                                         cv::Size projector_size, const ScanContext& context,
                                         const std::vector<StageReport>& stages) {
  return CorrespondenceChunks(scan_id, decoded, projector_size, context, stages).All();
}

Status AddChunk(const correspondence_t& m, DecodeResult* decoded, cv::Size* projector_size) {
  Status s = CheckRows("CORRESPONDENCE", m.width, m.height, m.row_begin, m.row_count, m.n,
                       m.chunk_index, m.chunk_count);
  if (!s.ok()) return s;
  if (m.projector_width <= 0 || m.projector_height <= 0) {
    return Status::Error("CORRESPONDENCE: bad projector size");
  }
  if (m.namplitude != 0 && m.namplitude != m.n) {
    return Status::Error("CORRESPONDENCE: " + std::to_string(m.namplitude) + " amplitudes for " +
                         std::to_string(m.n) + " pixels");
  }
  if (m.lit < 0 || m.lit > static_cast<int64_t>(m.width) * m.height) {
    return Status::Error("CORRESPONDENCE: " + std::to_string(m.lit) + " lit pixels of " +
                         std::to_string(m.width) + "x" + std::to_string(m.height));
  }
  const cv::Size size(m.width, m.height);
  if (decoded->projector_x.empty()) {
    decoded->projector_x.create(size, CV_32F);
    decoded->projector_y.create(size, CV_32F);
    decoded->valid.create(size, CV_8U);
    if (m.namplitude > 0) {
      decoded->amplitude.create(size, CV_32F);
    } else {
      decoded->amplitude.release();
    }
    decoded->has_columns = m.has_columns;
    decoded->has_rows = m.has_rows;
    decoded->status = Status::Ok();
    decoded->stats.lit = m.lit;
    *projector_size = cv::Size(m.projector_width, m.projector_height);
  } else if (decoded->projector_x.size() != size || decoded->has_columns != m.has_columns ||
             decoded->has_rows != m.has_rows || decoded->stats.lit != m.lit ||
             decoded->amplitude.empty() != (m.namplitude == 0) ||
             *projector_size != cv::Size(m.projector_width, m.projector_height)) {
    return Status::Error("CORRESPONDENCE: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on sizes or axes");
  }
  for (int r = 0; r < m.row_count; ++r) {
    const int y = m.row_begin + r;
    std::memcpy(decoded->projector_x.ptr<float>(y), &m.projector_x[r * m.width], m.width * 4);
    std::memcpy(decoded->projector_y.ptr<float>(y), &m.projector_y[r * m.width], m.width * 4);
    std::memcpy(decoded->valid.ptr<uint8_t>(y), &m.valid[r * m.width], m.width);
    if (m.namplitude > 0) {
      std::memcpy(decoded->amplitude.ptr<float>(y), &m.amplitude[r * m.width], m.width * 4);
    }
  }
  return Status::Ok();
}

ChunkMaker<point_cloud_t> PointCloudChunks(int64_t scan_id, const cv::Mat& points,
                                           const cv::Mat& amplitude, const ScanContext& context,
                                           const std::vector<StageReport>& stages) {
  const int width = points.cols;
  const bool with_amplitude = amplitude.size() == points.size();
  const auto chunks =
      RowChunks(points.rows, static_cast<size_t>(width) * (with_amplitude ? 16 : 12));
  ChunkMaker<point_cloud_t> maker;
  maker.count = static_cast<int>(chunks.size());
  // The maps' headers (their pixels shared, not copied) and the rest by value.
  maker.make = [scan_id, points, amplitude, context_message = ToMessage(context), stages, chunks,
                with_amplitude, width](int c, point_cloud_t* out) {
    point_cloud_t& m = *out;
    m.utime = 0;
    m.scan_id = scan_id;
    m.chunk_index = c;
    m.chunk_count = static_cast<int32_t>(chunks.size());
    m.width = width;
    m.height = points.rows;
    m.row_begin = chunks[static_cast<size_t>(c)].first;
    m.row_count = chunks[static_cast<size_t>(c)].second;
    m.nxyz = 3 * m.row_count * width;
    m.xyz.resize(m.nxyz);
    for (int r = 0; r < m.row_count; ++r) {
      std::memcpy(&m.xyz[3 * r * width], points.ptr<float>(m.row_begin + r), 12 * width);
    }
    m.amplitude.resize(with_amplitude ? static_cast<size_t>(m.row_count) * width : 0);
    for (int r = 0; with_amplitude && r < m.row_count; ++r) {
      std::memcpy(&m.amplitude[r * width], amplitude.ptr<float>(m.row_begin + r), 4 * width);
    }
    m.namplitude = static_cast<int32_t>(m.amplitude.size());
    m.context = context_message;
    SetStages(stages, &m);
  };
  return maker;
}

std::vector<point_cloud_t> ToMessages(int64_t scan_id, const cv::Mat& points,
                                      const cv::Mat& amplitude, const ScanContext& context,
                                      const std::vector<StageReport>& stages) {
  return PointCloudChunks(scan_id, points, amplitude, context, stages).All();
}

Status AddChunk(const point_cloud_t& m, cv::Mat* points, cv::Mat* amplitude) {
  if (m.nxyz % 3 != 0) return Status::Error("POINT_CLOUD: nxyz is not a multiple of 3");
  Status s = CheckRows("POINT_CLOUD", m.width, m.height, m.row_begin, m.row_count, m.nxyz / 3,
                       m.chunk_index, m.chunk_count);
  if (!s.ok()) return s;
  if (m.namplitude != 0 && m.namplitude != m.nxyz / 3) {
    return Status::Error("POINT_CLOUD: " + std::to_string(m.namplitude) + " amplitudes for " +
                         std::to_string(m.nxyz / 3) + " points");
  }
  const cv::Size size(m.width, m.height);
  const bool first = points->empty();
  if (first) {
    points->create(size, CV_32FC3);
  } else if (points->size() != size) {
    return Status::Error("POINT_CLOUD: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on the size");
  }
  for (int r = 0; r < m.row_count; ++r) {
    std::memcpy(points->ptr<float>(m.row_begin + r), &m.xyz[3 * r * m.width], 12 * m.width);
  }
  if (!amplitude) return Status::Ok();
  if (first) {
    if (m.namplitude > 0) {
      amplitude->create(size, CV_32F);
    } else {
      amplitude->release();
    }
  } else if (amplitude->empty() != (m.namplitude == 0)) {
    return Status::Error("POINT_CLOUD: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on the amplitude");
  }
  for (int r = 0; r < m.row_count && m.namplitude > 0; ++r) {
    std::memcpy(amplitude->ptr<float>(m.row_begin + r), &m.amplitude[r * m.width], 4 * m.width);
  }
  return Status::Ok();
}

std::vector<mesh_t> ToMessages(int64_t scan_id, const Mesh& mesh, bool bend_springs,
                               const FlattenResult& flattened, const ScanContext& context,
                               const std::vector<StageReport>& stages, const SheetPage& page) {
  const std::vector<cv::Point2d>& flat = flattened.flat;
  const scan_context_t context_message = ToMessage(context);
  // The mask's runs of page pixels: row, first column, length.
  std::vector<int32_t> runs;
  for (int v = 0; v < page.mask.rows; ++v) {
    const uint8_t* row = page.mask.ptr<uint8_t>(v);
    for (int u = 0; u < page.mask.cols;) {
      if (!row[u]) {
        ++u;
        continue;
      }
      const int first = u;
      while (u < page.mask.cols && row[u]) ++u;
      runs.insert(runs.end(), {v, first, u - first});
    }
  }
  // Up to six springs a node (two structural, two shear, two bend), each with its rest length.
  const auto chunks = RowChunks(mesh.rows, static_cast<size_t>(mesh.cols) * (41 + 6 * 8));
  std::vector<mesh_t> out(chunks.size());
  // The springs come in the order of their first node's row (ConnectSheet's): each chunk takes
  // those whose first node lies in its rows.
  size_t spring = 0;
  for (size_t c = 0; c < chunks.size(); ++c) {
    mesh_t& m = out[c];
    m.utime = 0;
    m.scan_id = scan_id;
    m.chunk_index = static_cast<int32_t>(c);
    m.chunk_count = static_cast<int32_t>(chunks.size());
    m.cols = mesh.cols;
    m.rows = mesh.rows;
    m.row_begin = chunks[c].first;
    m.row_count = chunks[c].second;
    m.bend_springs = bend_springs;
    m.n = m.row_count * mesh.cols;
    m.kind.resize(m.n);
    m.npoint = 3 * m.n;
    m.point.resize(m.npoint);
    m.nflat = 2 * m.n;
    m.flat.resize(m.nflat);
    for (int k = 0; k < m.n; ++k) {
      const int node = m.row_begin * mesh.cols + k;
      m.kind[k] = static_cast<int8_t>(mesh.kind[node]);
      for (int d = 0; d < 3; ++d) m.point[3 * k + d] = mesh.point[node][d];
      m.flat[2 * k] = flat[node].x;
      m.flat[2 * k + 1] = flat[node].y;
    }
    m.page = page.name;
    m.page_index = page.index;
    m.page_count = page.count;
    m.mask_width = page.mask.cols;
    m.mask_height = page.mask.rows;
    if (c == 0) m.runs = runs;
    m.nruns = static_cast<int32_t>(m.runs.size());
    const int row_end = m.row_begin + m.row_count;
    while (spring < mesh.springs.size() && mesh.springs[spring].a / mesh.cols < row_end) {
      m.rest_mm.push_back(mesh.springs[spring++].rest_mm);
    }
    m.nrest = static_cast<int32_t>(m.rest_mm.size());
    m.mean_strain = flattened.mean_strain;
    m.max_strain = flattened.max_strain;
    m.context = context_message;
    SetStages(stages, &m);
  }
  return out;
}

Status AddChunk(const mesh_t& m, Mesh* mesh, FlattenResult* flattened, SheetPage* page,
                SheetRests* rests) {
  std::vector<cv::Point2d>* flat = &flattened->flat;
  Status s = CheckRows("FLAT_MESH", m.cols, m.rows, m.row_begin, m.row_count, m.n, m.chunk_index,
                       m.chunk_count);
  if (!s.ok()) return s;
  if (m.cols < 2 || m.rows < 2) return Status::Error("FLAT_MESH: a grid needs 2x2 nodes");
  if (!(m.mean_strain >= 0 && m.max_strain >= m.mean_strain && std::isfinite(m.max_strain))) {
    return Status::Error("FLAT_MESH: strains mean " + std::to_string(m.mean_strain) + " and max " +
                         std::to_string(m.max_strain) + " are not a flattening's");
  }
  for (double rest : m.rest_mm) {
    if (!(rest > 0 && std::isfinite(rest))) {
      return Status::Error("FLAT_MESH: chunk " + std::to_string(m.chunk_index) +
                           " holds a spring rest length of " + std::to_string(rest) + " mm");
    }
  }
  if (rests) rests->by_first_row[m.row_begin] = m.rest_mm;
  flattened->mean_strain = m.mean_strain;
  flattened->max_strain = m.max_strain;
  flattened->status = Status::Ok();
  if (m.npoint != 3 * static_cast<int64_t>(m.n) || m.nflat != 2 * static_cast<int64_t>(m.n)) {
    return Status::Error("FLAT_MESH: " + std::to_string(m.n) + " nodes need " +
                         std::to_string(3 * m.n) + " point and " + std::to_string(2 * m.n) +
                         " flat values");
  }
  const size_t total = static_cast<size_t>(m.cols) * m.rows;
  if (mesh->kind.empty()) {
    mesh->cols = m.cols;
    mesh->rows = m.rows;
    mesh->kind.assign(total, NodeKind::kOff);
    mesh->point.assign(total, cv::Vec3d(0, 0, 0));
    flat->assign(total, cv::Point2d(0, 0));
  } else if (mesh->cols != m.cols || mesh->rows != m.rows) {
    return Status::Error("FLAT_MESH: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on the grid size");
  }
  for (int k = 0; k < m.n; ++k) {
    const size_t node = static_cast<size_t>(m.row_begin) * m.cols + k;
    if (m.kind[k] < 0 || m.kind[k] > static_cast<int8_t>(NodeKind::kSkirt)) {
      return Status::Error("FLAT_MESH: node " + std::to_string(node) + " has unknown kind " +
                           std::to_string(m.kind[k]));
    }
    mesh->kind[node] = static_cast<NodeKind>(m.kind[k]);
    mesh->point[node] = cv::Vec3d(m.point[3 * k], m.point[3 * k + 1], m.point[3 * k + 2]);
    (*flat)[node] = cv::Point2d(m.flat[2 * k], m.flat[2 * k + 1]);
    if (mesh->kind[node] != NodeKind::kOff &&
        !(std::isfinite(m.flat[2 * k]) && std::isfinite(m.flat[2 * k + 1]))) {
      return Status::Error("FLAT_MESH: node " + std::to_string(node) +
                           " has a non-finite flat position");
    }
  }
  if (m.page_count < 1 || m.page_count > 2 || m.page_index < 0 || m.page_index >= m.page_count) {
    return Status::Error("FLAT_MESH: page " + std::to_string(m.page_index) + " of " +
                         std::to_string(m.page_count));
  }
  if (m.mask_width <= 0 || m.mask_height <= 0 || m.mask_width > 65535 || m.mask_height > 65535 ||
      static_cast<int64_t>(m.mask_width) * m.mask_height > kMaxViewPixels || m.nruns % 3 != 0) {
    return Status::Error("FLAT_MESH: bad page mask (" + std::to_string(m.mask_width) + "x" +
                         std::to_string(m.mask_height) + ", " + std::to_string(m.nruns) +
                         " run values)");
  }
  if (page->mask.empty()) {
    page->mask = cv::Mat::zeros(m.mask_height, m.mask_width, CV_8U);
  } else if (page->mask.size() != cv::Size(m.mask_width, m.mask_height)) {
    return Status::Error("FLAT_MESH: chunk " + std::to_string(m.chunk_index) +
                         " disagrees with the first chunk on the page mask's size");
  }
  page->name = m.page;
  page->index = m.page_index;
  page->count = m.page_count;
  for (int k = 0; k < m.nruns; k += 3) {
    const int v = m.runs[k], first = m.runs[k + 1], length = m.runs[k + 2];
    if (v < 0 || v >= m.mask_height || first < 0 || length <= 0 || length > m.mask_width - first) {
      return Status::Error("FLAT_MESH: page mask run " + std::to_string(k / 3) +
                           " lies outside the " + std::to_string(m.mask_width) + "x" +
                           std::to_string(m.mask_height) + " mask");
    }
    page->mask(cv::Rect(first, v, length, 1)).setTo(255);
  }
  return Status::Ok();
}

Status SetRestLengths(const SheetRests& rests, Mesh* mesh) {
  // Each chunk's rest lengths in turn, as the springs reach its rows.
  std::map<int, size_t> used;
  for (Spring& s : mesh->springs) {
    const int row = s.a / mesh->cols;
    auto chunk = rests.by_first_row.upper_bound(row);
    if (chunk == rests.by_first_row.begin()) {
      return Status::Error("FLAT_MESH: no chunk carried the rest lengths of row " +
                           std::to_string(row) + "'s springs");
    }
    --chunk;
    size_t& next = used[chunk->first];
    if (next >= chunk->second.size()) {
      return Status::Error("FLAT_MESH: the chunk from row " + std::to_string(chunk->first) +
                           " carried " + std::to_string(chunk->second.size()) +
                           " rest lengths, fewer than the sheet's springs there");
    }
    s.rest_mm = chunk->second[next++];
  }
  for (const auto& [row, values] : rests.by_first_row) {
    if (used[row] != values.size()) {
      return Status::Error("FLAT_MESH: the chunk from row " + std::to_string(row) + " carried " +
                           std::to_string(values.size()) + " rest lengths for " +
                           std::to_string(used[row]) + " springs");
    }
  }
  return Status::Ok();
}

}  // namespace vellum::station
