// The station library without processes: message conversions and their validation, row
// chunking under the bus's size limit, reassembly that names what is missing, capture sets,
// scan logs <-> scan directories, and the node shell on LCM's in-process memq:// bus.
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "core/mesh/mesh.h"
#include "core/sim/gantry.h"
#include "station/assembler.h"
#include "station/contact_sheet.h"
#include "station/messages.h"
#include "station/node.h"
#include "station/scan_log.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "station/testing.h"
#include "vellum/calibration_v1_t.hpp"
#include "vellum/pattern_shown_v1_t.hpp"
#include "vellum/point_cloud_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/scan_started_v1_t.hpp"
#include "vellum/scan_started_v2_t.hpp"
#include "vellum/scan_started_v4_t.hpp"
#include "vellum/status_t.hpp"
#include "vellum/texture_t.hpp"
#include "vellum/texture_v1_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;

using testing::SameBits;

// Gray and colour at 8 and 16 bits a sample (a deeper camera's texture) come back bit for bit,
// each under its own FourCC; the 16-bit ones little-endian as V4L2's Y16 is.
TEST(Messages, ImagesRoundTripGrayAndColourAtEightAndSixteenBitsAndBadImagesAreNamed) {
  cv::Mat gray(37, 53, CV_8U), bgr(20, 31, CV_8UC3), gray16(23, 17, CV_16U), bgr16(9, 14, CV_16UC3);
  cv::randu(gray, 0, 256);
  cv::randu(bgr, 0, 256);
  cv::randu(gray16, 0, 65536);
  cv::randu(bgr16, 0, 65536);
  const int32_t formats[] = {image_t::PIXEL_FORMAT_GRAY, image_t::PIXEL_FORMAT_BGR,
                             image_t::PIXEL_FORMAT_GRAY16, image_t::PIXEL_FORMAT_BGR48};
  const cv::Mat images[] = {gray, bgr, gray16, bgr16};
  for (int k = 0; k < 4; ++k) {
    image_t msg;
    ToMessage(images[k], &msg);
    EXPECT_EQ(msg.pixelformat, formats[k]) << k;
    cv::Mat back;
    ASSERT_TRUE(FromMessage(msg, &back).ok());
    EXPECT_TRUE(SameBits(images[k], back)) << k;
  }
  image_t deep;
  gray16.at<uint16_t>(0, 0) = 0x1234;
  ToMessage(gray16, &deep);
  EXPECT_EQ(deep.data[0], 0x34);  // Little-endian.
  EXPECT_EQ(deep.data[1], 0x12);
  deep.size -= 2;  // A 16-bit row is two bytes a sample: one sample short is named.
  deep.data.resize(deep.size);
  EXPECT_NE(FromMessage(deep, &gray16).message().find("needs"), std::string::npos);
  image_t msg;
  ToMessage(gray, &msg);
  msg.row_stride = 60;  // Rows padded: data too short now.
  Status s = FromMessage(msg, &gray);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("needs"), std::string::npos) << s.message();
  ToMessage(bgr, &msg);
  msg.pixelformat = 0x47504a4d;  // 'MJPG'
  s = FromMessage(msg, &bgr);
  EXPECT_NE(s.message().find("'MJPG' is not supported"), std::string::npos) << s.message();
}

TEST(Messages, CorrespondenceChunksStayUnderTheLimitAndReassembleBitExactly) {
  DecodeResult d;
  const cv::Size size(1600, 1200);
  d.projector_x.create(size, CV_32F);
  d.projector_y.create(size, CV_32F);
  cv::randu(d.projector_x, 0, 1024);
  cv::randu(d.projector_y, 0, 768);
  d.projector_x(cv::Rect(10, 10, 50, 50)).setTo(std::numeric_limits<float>::quiet_NaN());
  d.valid = d.projector_x == d.projector_x;
  d.amplitude.create(size, CV_32F);
  cv::randu(d.amplitude, 0, 127.5);
  d.has_columns = d.has_rows = true;
  StageReport stage;
  stage.stage = "decode";
  stage.Number("pixels", "decoded", 12345);
  stage.outputs = {"nothing.txt"};
  d.stats.lit = 1500000;
  ScanContext context;
  context.identity.shelfmark = "MS 12";
  context.identity.folio = "4";
  context.identity.side = "verso";
  context.leaf_hint = cv::Rect(100, 80, 900, 700);
  context.object = ObjectKind::kBook;
  context.calibration_sha256 = std::string(64, 'a');
  context.scale_error_percent = 0.03;
  std::vector<correspondence_t> chunks = ToMessages(7, d, cv::Size(1024, 768), context, {stage});
  ASSERT_GT(chunks.size(), 10u);  // 25 MB in all.
  DecodeResult back;
  cv::Size projector;
  ChunkSet set;
  std::reverse(chunks.begin(), chunks.end());  // Any order.
  for (const correspondence_t& c : chunks) {
    EXPECT_LE(static_cast<size_t>(c.getEncodedSize()), kMaxMessageBytes + 1024);
    std::vector<StageReport> stages;
    ASSERT_TRUE(FromMessages(c.stages, &stages).ok());
    ASSERT_EQ(stages.size(), 1u);
    EXPECT_EQ(stages[0].stage, "decode");
    ASSERT_EQ(stages[0].values.size(), 1u);
    EXPECT_EQ(stages[0].values[0].number, 12345);
    EXPECT_EQ(stages[0].outputs, stage.outputs);
    ScanContext carried;
    ASSERT_TRUE(FromMessage(c.context, &carried).ok());
    EXPECT_EQ(carried.identity.shelfmark, "MS 12");
    EXPECT_EQ(carried.identity.side, "verso");
    EXPECT_EQ(carried.leaf_hint, context.leaf_hint);
    EXPECT_EQ(carried.object, ObjectKind::kBook);
    EXPECT_EQ(carried.calibration_sha256, context.calibration_sha256);
    EXPECT_EQ(carried.scale_error_percent, 0.03);
    ASSERT_TRUE(set.Add(c.scan_id, c.chunk_index, c.chunk_count, Clock::time_point()).ok());
    ASSERT_TRUE(AddChunk(c, &back, &projector).ok());
  }
  EXPECT_EQ(back.stats.lit, 1500000);
  EXPECT_TRUE(set.Complete());
  EXPECT_EQ(projector, cv::Size(1024, 768));
  EXPECT_TRUE(SameBits(d.projector_x, back.projector_x));
  EXPECT_TRUE(SameBits(d.amplitude, back.amplitude));
  EXPECT_TRUE(SameBits(d.projector_y, back.projector_y));
  EXPECT_TRUE(SameBits(d.valid, back.valid));

  correspondence_t bad = chunks[0];
  bad.row_begin = 1190;  // Rows past the image.
  EXPECT_NE(AddChunk(bad, &back, &projector).message().find("outside"), std::string::npos);
  bad = chunks[0];
  bad.n -= 1;
  EXPECT_FALSE(AddChunk(bad, &back, &projector).ok());
}

TEST(Messages, ALengthFieldLargerThanTheMessageIsRefusedBeforeAllocating) {
  point_cloud_t m{};
  m.nxyz = 3;
  m.xyz = {1, 2, 3};
  std::vector<uint8_t> bytes(m.getEncodedSize());
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  // nxyz sits after the fingerprint, utime and seq, the station (an empty string: a 4-byte
  // length and its NUL), scan_id and 6 int32 fields: claim 10^9 floats.
  const size_t at = 8 + 2 * 8 + 5 + 8 + 6 * 4;
  const uint32_t huge = 1000000000u;
  for (int k = 0; k < 4; ++k) bytes[at + k] = static_cast<uint8_t>(huge >> (24 - 8 * k));
  point_cloud_t back;
  EXPECT_FALSE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &back));
  EXPECT_LT(back.xyz.capacity(), 1000u);  // Refused before sizing the array.
}

TEST(Messages, ChunkSetNamesMissingAndDuplicateChunksAndGoesStaleByTheClockItIsGiven) {
  SteppedClock clock;
  ChunkSet set;
  ASSERT_TRUE(set.Add(3, 0, 5, clock.Now()).ok());
  clock.Advance(2);
  ASSERT_TRUE(set.Add(3, 4, 5, clock.Now()).ok());
  EXPECT_FALSE(set.Complete());
  EXPECT_EQ(set.Missing(), "chunks 1, 2, 3 of 5 missing");
  EXPECT_NE(set.Add(3, 4, 5, clock.Now()).message().find("came twice"), std::string::npos);
  EXPECT_FALSE(set.Add(3, 1, 6, clock.Now()).ok());  // Another count.
  EXPECT_FALSE(set.Add(4, 1, 5, clock.Now()).ok());  // Another scan.
  EXPECT_FALSE(set.Add(3, 5, 5, clock.Now()).ok());  // Out of range.
  // Stale counts from the last chunk that came, not the first.
  clock.Advance(0.9);
  EXPECT_FALSE(set.Stale(1, clock.Now()));
  clock.Advance(0.2);
  EXPECT_TRUE(set.Stale(1, clock.Now()));
}

TEST(Messages, PointCloudAndFlatMeshRoundTripToTheSameSheet) {
  const Calibration rig = DefaultRig();
  // A synthetic organised point map: a gentle cylinder over the camera's view.
  cv::Mat points(120, 160, CV_32FC3);
  for (int v = 0; v < points.rows; ++v) {
    for (int u = 0; u < points.cols; ++u) {
      const float x = (u - 80) * 1.0f, y = (60 - v) * 1.0f;
      points.at<cv::Vec3f>(v, u) = cv::Vec3f(x, y, 0.002f * x * x);
    }
  }
  std::vector<point_cloud_t> pc = ToMessages(9, points, cv::Mat(), ScanContext(), {});
  cv::Mat back, no_amplitude;
  for (const point_cloud_t& m : pc) ASSERT_TRUE(AddChunk(m, &back, &no_amplitude).ok());
  EXPECT_TRUE(SameBits(points, back));
  EXPECT_TRUE(no_amplitude.empty());
  // With the decoder's amplitude (for the albedo), which comes back bit for bit.
  cv::Mat amplitude(points.size(), CV_32F);
  cv::randu(amplitude, 0, 127.5);
  cv::Mat back2, amplitude_back;
  for (const point_cloud_t& m : ToMessages(9, points, amplitude, ScanContext(), {})) {
    ASSERT_TRUE(AddChunk(m, &back2, &amplitude_back).ok());
  }
  EXPECT_TRUE(SameBits(points, back2));
  EXPECT_TRUE(SameBits(amplitude, amplitude_back));

  Mesh mesh;
  mesh.cols = 6;
  mesh.rows = 5;
  mesh.kind.assign(30, NodeKind::kMeasured);
  mesh.kind[0] = NodeKind::kOff;
  mesh.kind[7] = NodeKind::kFilled;
  mesh.point.assign(30, cv::Vec3d(0, 0, 0));
  FlattenResult flattened;
  flattened.mean_strain = 0.0012;
  flattened.max_strain = 0.031;
  std::vector<cv::Point2d>& flat = flattened.flat;
  flat.resize(30);
  for (int k = 0; k < 30; ++k) {
    mesh.point[k] = cv::Vec3d(10.0 * (k % 6), 10.0 * (k / 6), 0.1 * k);
    flat[k] = cv::Point2d(mesh.point[k][0], mesh.point[k][1]);
  }
  auto project = [&](const cv::Vec3d& x) { return rig.camera.Project(x); };
  ConnectSheet(true, project, &mesh);
  ASSERT_TRUE(mesh.status.ok()) << mesh.status.message();
  // Rest lengths measured along the surface, not the nodes' straight distances: they travel.
  for (size_t k = 0; k < mesh.springs.size(); k += 3) mesh.springs[k].rest_mm *= 1.01;
  SheetPage page;
  page.name = "right";
  page.index = 1;
  page.count = 2;
  page.mask = cv::Mat::zeros(120, 160, CV_8U);
  cv::circle(page.mask, {70, 60}, 40, cv::Scalar(255), cv::FILLED);
  cv::circle(page.mask, {70, 60}, 10, cv::Scalar(0), cv::FILLED);  // A hole.
  Mesh received;
  FlattenResult received_flat;
  SheetPage received_page;
  SheetRests rests;
  for (const mesh_t& m : ToMessages(9, mesh, true, flattened, ScanContext(), {}, page)) {
    ASSERT_TRUE(AddChunk(m, &received, &received_flat, &received_page, &rests).ok());
  }
  EXPECT_EQ(received_page.name, "right");
  EXPECT_EQ(received_page.index, 1);
  EXPECT_EQ(received_page.count, 2);
  EXPECT_TRUE(SameBits(received_page.mask, page.mask));
  ConnectSheet(true, project, &received);
  ASSERT_TRUE(received.status.ok());
  ASSERT_TRUE(SetRestLengths(rests, &received).ok());
  ASSERT_EQ(received.springs.size(), mesh.springs.size());
  for (size_t k = 0; k < mesh.springs.size(); ++k) {
    EXPECT_EQ(received.springs[k].rest_mm, mesh.springs[k].rest_mm) << k;
  }
  // Rest lengths that do not number the springs are named.
  SheetRests short_of = rests;
  short_of.by_first_row.begin()->second.pop_back();
  EXPECT_NE(SetRestLengths(short_of, &received).message().find("fewer than the sheet's springs"),
            std::string::npos);
  EXPECT_EQ(received.springs.size(), mesh.springs.size());
  EXPECT_EQ(received.quads, mesh.quads);
  EXPECT_EQ(received.pixel, mesh.pixel);
  EXPECT_EQ(received_flat.flat, flat);
  EXPECT_TRUE(received_flat.status.ok());
  EXPECT_EQ(received_flat.mean_strain, 0.0012);
  EXPECT_EQ(received_flat.max_strain, 0.031);

  mesh_t bad = ToMessages(9, mesh, true, flattened, ScanContext(), {}, page)[0];
  bad.kind[3] = 9;
  Mesh m2;
  FlattenResult f2;
  SheetPage p2;
  EXPECT_NE(AddChunk(bad, &m2, &f2, &p2).message().find("unknown kind 9"), std::string::npos);
  bad = ToMessages(9, mesh, true, flattened, ScanContext(), {}, page)[0];
  bad.runs[2] = 1000;  // A run past the mask's edge.
  Mesh m3;
  SheetPage p3;
  EXPECT_NE(AddChunk(bad, &m3, &f2, &p3).message().find("lies outside"), std::string::npos);
  bad = ToMessages(9, mesh, true, flattened, ScanContext(), {}, page)[0];
  bad.max_strain = std::nan("");
  Mesh m4;
  SheetPage p4;
  EXPECT_NE(AddChunk(bad, &m4, &f2, &p4).message().find("not a flattening's"), std::string::npos);
}

TEST(Messages, AScanContextFromTheBusIsCheckedAndNamesWhatIsWrong) {
  ScanContext context;
  context.leaf_hint = cv::Rect(10, 20, 30, 40);
  context.calibration_sha256 = std::string(64, '0');
  scan_context_t m = ToMessage(context);
  ScanContext back;
  ASSERT_TRUE(FromMessage(m, &back).ok());
  EXPECT_EQ(back.leaf_hint, context.leaf_hint);
  EXPECT_EQ(back.object, ObjectKind::kAuto);
  EXPECT_TRUE(std::isnan(back.scale_error_percent));  // Not measured travels as not measured.
  auto error = [](const scan_context_t& bad) {
    ScanContext c;
    return FromMessage(bad, &c).message();
  };
  scan_context_t bad = m;
  bad.leaf_hint[2] = -5;
  EXPECT_NE(error(bad).find("leaf hint 10,20,-5,40"), std::string::npos) << error(bad);
  bad = m;
  bad.object = "scroll";
  EXPECT_NE(error(bad).find("unknown object 'scroll'"), std::string::npos) << error(bad);
  bad = m;
  bad.calibration_sha256 = "123";
  EXPECT_NE(error(bad).find("not a SHA-256"), std::string::npos) << error(bad);
  bad = m;
  bad.scale_error_percent = INFINITY;
  EXPECT_NE(error(bad).find("infinite"), std::string::npos) << error(bad);
  // No hint travels as no hint.
  bad = ToMessage(ScanContext());
  ASSERT_TRUE(FromMessage(bad, &back).ok());
  EXPECT_TRUE(back.leaf_hint.empty());
}

TEST(Messages, CalibrationRoundTripsAndNaNIsRejected) {
  const Calibration rig = DefaultRig();
  calibration_t msg;
  ToMessage(rig, &msg);
  Calibration back;
  ASSERT_TRUE(FromMessage(msg, &back).ok());
  EXPECT_EQ(back.camera.matrix, rig.camera.matrix);
  EXPECT_EQ(back.projector.translation, rig.projector.translation);
  msg.projector.rotation[4] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(FromMessage(msg, &back).message().find("not all numbers are finite"),
            std::string::npos);
}

// The working volume and the measured scale error travel with the calibration (a station's scan
// triangulates and reports as `vellum process` with the calibration file does); a CALIBRATION
// recorded before they did decodes with the default volume and no measured error.
TEST(Messages, TheWorkingVolumeAndScaleErrorTravelAndAnOldCalibrationStillDecodes) {
  Calibration rig = DefaultRig();
  rig.min_z_mm = -5;
  rig.max_z_mm = 80;
  rig.scale_error_percent = 0.07;
  calibration_t msg{};
  ToMessage(rig, &msg);
  Calibration back;
  ASSERT_TRUE(FromMessage(msg, &back).ok());
  EXPECT_EQ(back.min_z_mm, -5);
  EXPECT_EQ(back.max_z_mm, 80);
  EXPECT_EQ(back.scale_error_percent, 0.07);
  msg.max_z_mm = -10;
  EXPECT_NE(FromMessage(msg, &back).message().find("working volume"), std::string::npos);
  msg.max_z_mm = 80;
  msg.scale_error_percent = -1;
  EXPECT_NE(FromMessage(msg, &back).message().find("scale_error_percent"), std::string::npos);
  // As recorded before: the same fields up to the projector.
  calibration_v1_t old{};
  old.scan_id = 5;
  old.source = "old rig";
  ToMessage(rig, &msg);
  old.camera = msg.camera;
  old.projector = msg.projector;
  const std::vector<uint8_t> bytes = Encode(old);
  calibration_t decoded;
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &decoded));
  EXPECT_EQ(decoded.source, "old rig");
  ASSERT_TRUE(FromMessage(decoded, &back).ok());
  EXPECT_EQ(back.min_z_mm, Calibration().min_z_mm);
  EXPECT_EQ(back.max_z_mm, Calibration().max_z_mm);
  EXPECT_TRUE(std::isnan(back.scale_error_percent));
  EXPECT_EQ(back.camera.matrix, rig.camera.matrix);
}

// A SCAN_STARTED as logs recorded it before the live view's word (v4), the leaf hint (v2) and the
// extra lights (v1) still reads: the same scan, nothing seen off the view, no hint (and no lights);
// and the hint as the viewer sends it turns into camera pixels, while one that is not a region of
// the view is none.
TEST(Messages, EarlierScanStartedLayoutsReadAndTheLeafHintIsARegionOfTheView) {
  scan_started_v2_t v2{};
  v2.scan_id = 41;
  v2.session = 7;
  v2.pattern_count = 58;
  v2.identity.shelfmark = "MS 12";
  v2.light_count = 1;
  v2.lights.resize(1);
  v2.lights[0].name = "uv";
  std::vector<uint8_t> bytes = Encode(v2);
  scan_started_t m;
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &m));
  EXPECT_EQ(m.scan_id, 41);
  EXPECT_EQ(m.session, 7);
  EXPECT_EQ(m.pattern_count, 58);
  EXPECT_EQ(m.identity.shelfmark, "MS 12");
  ASSERT_EQ(m.light_count, 1);
  EXPECT_EQ(m.lights[0].name, "uv");
  EXPECT_EQ(m.leaf_hint[2], 0.0f);
  scan_started_v1_t v1{};
  v1.scan_id = 42;
  v1.identity.folio = "3";
  bytes = Encode(v1);
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &m));
  EXPECT_EQ(m.scan_id, 42);
  EXPECT_EQ(m.identity.folio, "3");
  EXPECT_EQ(m.light_count, 0);
  EXPECT_EQ(m.leaf_hint[2], 0.0f);
  // Before the live view's word on the edge (v4): the hint and the object kept, nothing seen off.
  scan_started_v4_t v4{};
  v4.scan_id = 43;
  v4.leaf_hint[2] = 0.5f;
  v4.object = "book";
  bytes = Encode(v4);
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &m));
  EXPECT_EQ(m.scan_id, 43);
  EXPECT_EQ(m.leaf_hint[2], 0.5f);
  EXPECT_EQ(m.object, "book");
  EXPECT_EQ(m.live_off_view, "");

  const cv::Size camera(1600, 1200);
  const float hint[4] = {0.6875f, 0.25f, 0.125f, 0.5f};
  EXPECT_EQ(LeafHintPixels(hint, camera), cv::Rect(1100, 300, 200, 600));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const std::array<float, 4>& bad :
       {std::array<float, 4>{0, 0, 0, 0}, std::array<float, 4>{nan, 0.1f, 0.2f, 0.2f},
        std::array<float, 4>{0.9f, 0.1f, 0.2f, 0.2f}, std::array<float, 4>{-0.1f, 0.1f, 0.2f, 0.2f},
        std::array<float, 4>{0.1f, 0.1f, 0.2f, -0.2f}}) {
    EXPECT_TRUE(LeafHintPixels(bad.data(), camera).empty())
        << bad[0] << "," << bad[1] << "," << bad[2] << "," << bad[3];
  }
}

// A PATTERN_SHOWN recorded before it said when the image was handed to the display reads with
// handed_utime 0 (not said), everything else kept.
TEST(Messages, AnEarlierPatternShownReadsWithItsHandoverNotSaid) {
  pattern_shown_v1_t v1{};
  v1.utime = 1234;
  v1.scan_id = 44;
  v1.pattern_index = 7;
  v1.pattern_count = 40;
  v1.projector_width = 800;
  v1.projector_height = 600;
  const std::vector<uint8_t> bytes = Encode(v1);
  pattern_shown_t m{};
  m.handed_utime = 99;
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &m));
  EXPECT_EQ(m.utime, 1234);
  EXPECT_EQ(m.scan_id, 44);
  EXPECT_EQ(m.pattern_index, 7);
  EXPECT_EQ(m.projector_width, 800);
  EXPECT_EQ(m.handed_utime, 0);
  pattern_shown_t now{};
  now.handed_utime = 1000;
  now.utime = 1034;
  const std::vector<uint8_t> current = Encode(now);
  ASSERT_TRUE(SafeDecode(current.data(), static_cast<int64_t>(current.size()), &m));
  EXPECT_EQ(m.handed_utime, 1000);
}

// A texture's chunks say their bits: a 16-bit texture comes back bit for bit; a chunk that
// disagrees with the first on its bits, or says bits other than 8 or 16, is refused, named. A
// TEXTURE recorded before it said them (texture_v1_t) reads as 8-bit.
TEST(Messages, TextureChunksCarrySixteenBitsAndAnEarlierTextureReadsAsEightBit) {
  cv::Mat texture(300, 1000, CV_16UC3);  // 1.8 MB: several chunks.
  cv::randu(texture, 0, 65536);
  std::vector<texture_t> chunks = TextureMessages(5, texture);
  ASSERT_GT(chunks.size(), 1u);
  cv::Mat back;
  for (const texture_t& m : chunks) {
    EXPECT_EQ(m.bits, 16);
    ASSERT_TRUE(AddChunk(m, &back).ok());
  }
  EXPECT_TRUE(SameBits(texture, back));
  cv::Mat eight(300, 1000, CV_8UC3, cv::Scalar::all(7));
  texture_t mixed = TextureMessages(5, eight)[0];
  cv::Mat partial;
  ASSERT_TRUE(AddChunk(chunks[1], &partial).ok());
  EXPECT_NE(AddChunk(mixed, &partial).message().find("bits"), std::string::npos);
  mixed.bits = 12;
  EXPECT_NE(AddChunk(mixed, &partial).message().find("12 bits a sample (8 or 16)"),
            std::string::npos);

  texture_v1_t v1{};
  v1.scan_id = 6;
  v1.chunk_count = 1;
  v1.width = 4;
  v1.height = 2;
  v1.row_count = 2;
  v1.channels = 1;
  v1.size = 8;
  v1.data.assign({1, 2, 3, 4, 5, 6, 7, 8});
  const std::vector<uint8_t> bytes = Encode(v1);
  texture_t m{};
  ASSERT_TRUE(SafeDecode(bytes.data(), static_cast<int64_t>(bytes.size()), &m));
  EXPECT_EQ(m.bits, 8);
  cv::Mat old;
  ASSERT_TRUE(AddChunk(m, &old).ok());
  EXPECT_EQ(old.type(), CV_8U);
  EXPECT_EQ(old.at<uint8_t>(1, 3), 8);
}

Scan SmallScan() {
  PatternOptions options;
  options.projector_size = cv::Size(64, 48);
  options.phase_steps = 4;
  Scan scan;
  scan.sequence = MakePatternSequence(options);
  scan.camera_size = cv::Size(40, 30);
  scan.texture.create(30, 40, CV_8UC3);
  cv::randu(scan.texture, 0, 256);
  for (size_t k = 0; k < scan.sequence.patterns.size(); ++k) {
    cv::Mat f(30, 40, CV_8U);
    cv::randu(f, 0, 256);
    scan.frames.push_back(f);
  }
  return scan;
}

TEST(ScanStore, CaptureSetNamesWhatIsMissingAndRejectsMismatches) {
  const Scan scan = SmallScan();
  const int n = static_cast<int>(scan.frames.size());
  CaptureSet set;
  ASSERT_TRUE(set.Add(MakeCapture(scan, 5, -1, 1000)).ok());
  for (int k = 0; k < n; ++k) {
    if (k == 3 || k == 7) continue;
    ASSERT_TRUE(set.Add(MakeCapture(scan, 5, k, 2000 + k)).ok());
  }
  EXPECT_FALSE(set.Complete());
  EXPECT_EQ(set.Missing(), "2 of " + std::to_string(n + 1) + " captures missing (3, 7)");
  EXPECT_NE(set.Add(MakeCapture(scan, 5, 0, 1)).message().find("captured twice"),
            std::string::npos);
  capture_t other = MakeCapture(scan, 5, 3, 1);
  other.projector_width = 65;
  EXPECT_FALSE(set.Add(other).ok());
  Scan small = scan;
  cv::resize(small.frames[3], small.frames[3], cv::Size(20, 15));
  EXPECT_NE(set.Add(MakeCapture(small, 5, 3, 1)).message().find("image is 20x15"),
            std::string::npos);
}

TEST(ScanStore, ALogAndAScanDirectoryConvertBothWaysLosslessly) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_store_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const Scan scan = SmallScan();
  calibration_t calibration;
  ToMessage(DefaultRig(), &calibration);
  const std::string log = (dir / "scan.lcmlog").string();
  ASSERT_TRUE(WriteScanLog(log, scan, 77, kDefaultStation, &calibration).ok());
  Scan back;
  bool has_calibration = false;
  calibration_t calibration_back;
  int64_t id = 0;
  ASSERT_TRUE(ReadScanLog(log, 0, &back, &has_calibration, &calibration_back, &id).ok());
  EXPECT_EQ(id, 77);
  EXPECT_TRUE(has_calibration);
  EXPECT_EQ(back.sequence.patterns, scan.sequence.patterns);
  EXPECT_EQ(back.sequence.projector_size, scan.sequence.projector_size);
  EXPECT_TRUE(SameBits(back.texture, scan.texture));
  ASSERT_EQ(back.frames.size(), scan.frames.size());
  for (size_t k = 0; k < scan.frames.size(); ++k)
    EXPECT_TRUE(SameBits(back.frames[k], scan.frames[k]));

  // A log cut short names the missing captures.
  const auto size = fs::file_size(log);
  fs::resize_file(log, size - 1500);
  Status s = ReadScanLog(log, 0, &back, &has_calibration, &calibration_back, &id);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("incomplete"), std::string::npos) << s.message();
  EXPECT_FALSE(ReadScanLog((dir / "none.lcmlog").string(), 0, &back, &has_calibration,
                           &calibration_back, &id)
                   .ok());
  fs::remove_all(dir);
}

// A decoder killed in the middle of writing a capture leaves a torn last event; the restarted
// decoder's appends must stay readable after it (LCM's reader stops at the first bad header).
TEST(ScanStore, AppendingAfterATornEventKeepsEveryWholeEventReadable) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_torn_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const ScanFolder folder = ScanFolder::For(dir.string(), 9);
  auto count_events = [&] {
    lcm::LogFile log(folder.log(), "r");
    int n = 0;
    while (log.good() && log.readNextEvent()) ++n;
    return n;
  };
  const std::vector<uint8_t> bytes(5000, 7);
  {
    CaptureLog log;
    for (int k = 0; k < 3; ++k) ASSERT_TRUE(log.Append(folder, 9, "CAPTURE", k, bytes).ok());
    EXPECT_EQ(log.trimmed(), 0);
  }
  const auto whole = fs::file_size(folder.log());
  const int64_t event = static_cast<int64_t>(whole) / 3;
  // Torn in the data, then torn in the header: each is cut off, the whole events stay.
  for (const int64_t keep : {event - 100, int64_t{10}}) {
    fs::resize_file(folder.log(), whole);
    CaptureLog extra;  // A fourth event, then torn to `keep` of its bytes.
    ASSERT_TRUE(extra.Append(folder, 9, "CAPTURE", 3, bytes).ok());
    extra.Close();
    fs::resize_file(folder.log(), whole + keep);
    CaptureLog log;
    ASSERT_TRUE(log.Append(folder, 9, "CAPTURE", 4, bytes).ok());
    EXPECT_EQ(log.trimmed(), keep);
    ASSERT_TRUE(log.Append(folder, 9, "CAPTURE", 5, bytes).ok());
    EXPECT_EQ(log.trimmed(), 0);  // Said once, as the log is opened.
    log.Close();
    EXPECT_EQ(count_events(), 5) << "torn to " << keep << " bytes";
    EXPECT_EQ(fs::file_size(folder.log()), whole + 2 * event);
  }
  // Damage inside the log (not an event header where one should start) is not cut.
  fs::resize_file(folder.log(), whole);
  {
    std::fstream f(folder.log(), std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(event);
    f.put('x');
  }
  int64_t cut = -1;
  ASSERT_TRUE(TrimTornTail(folder.log(), &cut).ok());
  EXPECT_EQ(cut, 0);
  EXPECT_EQ(fs::file_size(folder.log()), whole);
  ASSERT_TRUE(TrimTornTail((dir / "none.lcmlog").string(), &cut).ok());  // No log yet.
  EXPECT_EQ(cut, 0);
  fs::remove_all(dir);
}

// A scan's folder may carry a readable slug after its id; the id alone finds it, and the ledger
// reads it.
TEST(ScanStore, ANamedScanFolderIsFoundByItsIdAlone) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_named_" + std::to_string(getpid()));
  fs::remove_all(dir);
  EXPECT_EQ(ScanFolder::For(dir.string(), 7).root, (dir / "scan-7").string());  // None yet.
  const ScanFolder named = ScanFolder::New(dir.string(), 7, "MS-12_3_recto");
  EXPECT_EQ(named.root, (dir / "scan-7-MS-12_3_recto").string());
  fs::create_directories(named.raw());
  fs::create_directories(dir / "scan-70-MS-1");  // Another id with the same first digits.
  EXPECT_EQ(ScanFolder::For(dir.string(), 7).root, named.root);
  EXPECT_EQ(ScanFolder::For(dir.string(), 70).root, (dir / "scan-70-MS-1").string());
  EXPECT_EQ(ScanFolder::For(dir.string(), 71).root, (dir / "scan-71").string());
  ASSERT_TRUE(MarkPending(ScanFolder::For(dir.string(), 7), 1).ok());
  EXPECT_EQ(FindPending(dir.string()), std::vector<int64_t>{7});
  // Moved away: not found by a stale memory of it.
  fs::rename(named.root, dir / "elsewhere");
  EXPECT_EQ(ScanFolder::For(dir.string(), 7).root, (dir / "scan-7").string());
  fs::remove_all(dir);
}

// A retake of a folio sets its earlier attempts aside in retaken/ (kept whole; found by id
// still), but not one still pending, nor another folio's, nor a scan without a name.
TEST(ScanStore, ARetakeSetsTheEarlierAttemptsAside) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_retake_" + std::to_string(getpid()));
  fs::remove_all(dir);
  for (const char* name : {"scan-10-MS-7_1_verso", "scan-11-MS-7_1_verso", "scan-12-MS-7_1_verso",
                           "scan-13-MS-7_2_recto", "scan-14", "scan-15-MS-7_1_verso_x"}) {
    fs::create_directories(dir / name / "raw");
    std::ofstream(dir / name / "raw" / "scan.yaml") << name;
  }
  std::ofstream(dir / "scan-12-MS-7_1_verso" / "pending") << "1\n";
  const std::vector<std::string> moved = SetAsideEarlierAttempts(dir.string(), 20, "MS-7_1_verso");
  EXPECT_EQ(moved.size(), 2u);
  for (const char* name : {"scan-10-MS-7_1_verso", "scan-11-MS-7_1_verso"}) {
    EXPECT_TRUE(fs::exists(dir / "retaken" / name / "raw" / "scan.yaml")) << name;
    EXPECT_FALSE(fs::exists(dir / name)) << name;
  }
  for (const char* name :
       {"scan-12-MS-7_1_verso", "scan-13-MS-7_2_recto", "scan-14", "scan-15-MS-7_1_verso_x"}) {
    EXPECT_TRUE(fs::exists(dir / name)) << name;
  }
  EXPECT_EQ(ScanFolder::For(dir.string(), 10).root,
            (dir / "retaken" / "scan-10-MS-7_1_verso").string());
  EXPECT_TRUE(SetAsideEarlierAttempts(dir.string(), 21, "").empty());
  EXPECT_EQ(ScanFolderId("scan-15-MS-7_1_verso_x"), 15);
  EXPECT_EQ(ScanFolderId("scan-x12"), 0);
  EXPECT_EQ(ScanFolderId("scan-12x"), 0);
  fs::remove_all(dir);
}

// The contact sheet tells a scan as it is: one restored while its folder is still marked
// pending (the restorer writes the sheet before the mark is cleared) by its report's verdict,
// not as pending; one that failed before its scan.yaml was written by the identity its log's
// SCAN_STARTED carried, not as a scan without one.
TEST(ContactSheet, ARestoredScanIsNotPendingAndAFailedOneKeepsItsIdentity) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_sheet_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const fs::path restored = dir / "scan-40-MS-7_4_recto";
  fs::create_directories(restored / "results");
  std::ofstream(restored / "pending") << "1\n";
  std::ofstream(restored / "results" / "report.json")
      << R"({"qc": {"verdict": "warn", "checks": [{"name": "scale", "verdict": "warn",
                                                  "detail": "leaf 190 x 240 mm"}]}})";
  Scan scan = SmallScan();
  scan.identity.shelfmark = "MS 7";
  scan.identity.folio = "4";
  scan.identity.side = "recto";
  fs::create_directories(restored / "raw");
  ASSERT_TRUE(WriteScanLog((restored / "raw" / "captures.lcmlog").string(), scan, 40,
                           kDefaultStation, nullptr)
                  .ok());
  const fs::path failed = dir / "scan-41-MS-7_4_verso";
  fs::create_directories(failed / "raw");
  scan.identity.side = "verso";
  ASSERT_TRUE(WriteScanLog((failed / "raw" / "captures.lcmlog").string(), scan, 41, kDefaultStation,
                           nullptr)
                  .ok());
  std::ofstream(failed / "raw" / "failed.txt") << "no capture for 30 s\n";
  const std::vector<SheetEntry> sheet = ReadSheet(dir.string());
  ASSERT_EQ(sheet.size(), 2u);
  EXPECT_EQ(sheet[1].scan_id, 40);
  EXPECT_EQ(sheet[1].state, "warn");
  EXPECT_NE(sheet[1].detail.find("scale: leaf 190"), std::string::npos) << sheet[1].detail;
  EXPECT_EQ(sheet[0].scan_id, 41);
  EXPECT_EQ(sheet[0].state, "failed");
  EXPECT_EQ(IdentityTitle(sheet[0].identity), "MS 7, 4 verso");
  ASSERT_TRUE(WriteContactSheet(dir.string()).ok());
  std::ifstream in(dir / "index.html");
  const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(html.find("MS 7, 4 verso"), std::string::npos);
  EXPECT_EQ(html.find("class=\"scan pending"), std::string::npos) << html;
  EXPECT_NE(html.find("class=\"scan warn"), std::string::npos) << html;
  EXPECT_EQ(html.find("(no identity)"), std::string::npos) << html;
  fs::remove_all(dir);
}

// The restorer writes the sheet before every RESTORED: a folder unchanged since the last sheet
// is not read again, and any change to what its entry is read from is seen (a verdict, a
// failure, a scan moved to retaken/, one gone), the same as a sheet read afresh.
TEST(ContactSheet, AScanFolderIsReadAgainOnlyWhenItChanged) {
  const fs::path dir =
      fs::temp_directory_path() / ("vellum_sheet_cache_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const auto report = [&](int id, const std::string& verdict) {
    const fs::path results = dir / ("scan-" + std::to_string(id)) / "results";
    fs::create_directories(results);
    std::ofstream(results / "report.json") << R"({"qc": {"verdict": ")" + verdict + R"("}})";
  };
  for (int id = 50; id < 60; ++id) report(id, "pass");
  const auto same_as_afresh = [&](const std::vector<SheetEntry>& cached) {
    const std::vector<SheetEntry> afresh = ReadSheet(dir.string());
    if (cached.size() != afresh.size()) return false;
    for (size_t k = 0; k < afresh.size(); ++k) {
      const SheetEntry &a = cached[k], &b = afresh[k];
      if (a.scan_id != b.scan_id || a.folder != b.folder || a.state != b.state ||
          a.detail != b.detail || a.retaken != b.retaken) {
        return false;
      }
    }
    return true;
  };
  SheetCache cache;
  EXPECT_TRUE(same_as_afresh(ReadSheet(dir.string(), &cache)));
  EXPECT_EQ(cache.reads, 10);
  EXPECT_TRUE(same_as_afresh(ReadSheet(dir.string(), &cache)));
  EXPECT_EQ(cache.reads, 10) << "nothing changed: nothing read again";
  report(53, "warn (a longer verdict: another size)");
  std::ofstream(dir / "scan-55" / "failed.txt");
  fs::create_directories(dir / "scan-56" / "raw");
  std::ofstream(dir / "scan-56" / "raw" / "failed.txt") << "no capture for 30 s\n";
  fs::create_directories(dir / "retaken");
  fs::rename(dir / "scan-57", dir / "retaken" / "scan-57");
  fs::remove_all(dir / "scan-58");
  report(60, "fail");
  std::vector<SheetEntry> sheet = ReadSheet(dir.string(), &cache);
  EXPECT_TRUE(same_as_afresh(sheet));
  EXPECT_EQ(cache.reads, 14) << "53, 56, the retaken 57 and the new 60";
  ASSERT_EQ(sheet.size(), 10u);
  EXPECT_EQ(sheet[0].scan_id, 60);
  EXPECT_EQ(sheet[0].state, "fail");
  EXPECT_EQ(cache.folders.size(), 10u) << "the one gone is dropped";
  fs::remove_all(dir);
}

TEST(ScanStore, PendingScansAreFoundWithTheirAttemptsUntilCleared) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_pending_" + std::to_string(getpid()));
  fs::remove_all(dir);
  EXPECT_TRUE(FindPending(dir.string()).empty());  // No data folder yet: nothing pending.
  for (int64_t id : {30, 4, 1000}) fs::create_directories(dir / ("scan-" + std::to_string(id)));
  fs::create_directories(dir / "scan-x12");  // Not a scan folder.
  std::ofstream(dir / "scan-x12" / "pending") << "1\n";
  const ScanFolder a = ScanFolder::For(dir.string(), 30), b = ScanFolder::For(dir.string(), 1000);
  EXPECT_EQ(PendingAttempts(a), 0);
  ASSERT_TRUE(MarkPending(a, 1).ok());
  ASSERT_TRUE(MarkPending(b, 1).ok());
  ASSERT_TRUE(MarkPending(b, 2).ok());
  EXPECT_EQ(FindPending(dir.string()), (std::vector<int64_t>{30, 1000}));
  EXPECT_EQ(PendingAttempts(a), 1);
  EXPECT_EQ(PendingAttempts(b), 2);
  ClearPending(b);
  EXPECT_EQ(FindPending(dir.string()), std::vector<int64_t>{30});
  EXPECT_EQ(PendingAttempts(b), 0);
  std::ofstream(a.pending()) << "garbage";  // Unreadable: still pending, one attempt made.
  EXPECT_EQ(PendingAttempts(a), 1);
  fs::remove_all(dir);
}

TEST(Node, ReportsUndecodableMessagesAndSequenceGapsOnItsStatus) {
  Node node("vellum-unit", "memq://");
  std::vector<status_t> statuses;
  node.Subscribe<status_t>("STATUS_UNIT", [&](const status_t& m) { statuses.push_back(m); });
  int received = 0;
  node.Subscribe<scan_request_t>("SCAN_REQUEST", [&](const scan_request_t&) { ++received; });
  const std::vector<uint8_t> junk(10, 1);
  node.lcm().publish("SCAN_REQUEST", junk.data(), static_cast<unsigned>(junk.size()));
  // A string whose length field is 0 makes lcm-gen's decoder throw (found by fuzzing).
  scan_request_t bad{};
  bad.station = kDefaultStation;
  std::vector<uint8_t> bytes(bad.getEncodedSize());
  bad.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  std::fill(bytes.begin() + 24, bytes.begin() + 28, 0);  // station's length (after 3 int64s).
  node.lcm().publish("SCAN_REQUEST", bytes.data(), static_cast<unsigned>(bytes.size()));
  // Another station's messages are not this one's: dropped, counted, not an error.
  scan_request_t other{};
  other.station = "gantry-2";
  other.seq = 40;
  node.lcm().publish("SCAN_REQUEST", &other);
  scan_request_t r{};
  r.station = kDefaultStation;
  for (int64_t seq : {0, 1, 5}) {
    r.seq = seq;
    node.lcm().publish("SCAN_REQUEST", &r);
  }
  for (int k = 0; k < 10; ++k) node.lcm().handleTimeout(10);
  EXPECT_EQ(received, 3);
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.back().process, "vellum-unit");
  EXPECT_EQ(statuses.back().errors, 3);
  EXPECT_NE(statuses.back().last_error.find("3 message(s) lost on the bus (seq 1 then 5)"),
            std::string::npos)
      << statuses.back().last_error;
  EXPECT_EQ(node.Counter("lost messages"), 3);
  EXPECT_EQ(node.Counter("from other stations"), 1);
  // Posted work runs in order, off the LCM thread.
  std::vector<int> order;
  for (int k = 0; k < 5; ++k) node.Post([&order, k] { order.push_back(k); });
  while (node.Pending() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 4}));
}

// Sequence gaps are tracked per publisher: a second publisher on a channel (another daemon, a
// restarted one, a replayed log), interleaved with the first, loses nothing; a gap in either is
// counted as what it is. Each process counts from a random start of its own.
TEST(Node, LostMessagesAreCountedPerPublisherNotPerChannel) {
  Node node("vellum-unit", "memq://");
  int received = 0;
  node.Subscribe<scan_request_t>("SCAN_REQUEST", [&](const scan_request_t&) { ++received; });
  scan_request_t r{};
  r.station = kDefaultStation;
  // The first counts from far away (as a random start puts it), the second from 1.
  constexpr int64_t kFar = 5'000'000'000;
  for (int64_t seq : std::vector<int64_t>{kFar, 1, kFar + 1, 2, kFar + 2, 3, 4, kFar + 3}) {
    r.seq = seq;
    node.lcm().publish("SCAN_REQUEST", &r);
  }
  for (int k = 0; k < 10; ++k) node.lcm().handleTimeout(10);
  EXPECT_EQ(received, 8);
  EXPECT_EQ(node.Counter("lost messages"), 0);
  for (int64_t seq : {int64_t{7}, kFar + 4}) {  // 5 and 6 lost from the second publisher.
    r.seq = seq;
    node.lcm().publish("SCAN_REQUEST", &r);
  }
  for (int k = 0; k < 10; ++k) node.lcm().handleTimeout(10);
  EXPECT_EQ(node.Counter("lost messages"), 2);
  // Two processes' counters start far apart (each heard on its own bus): a chance of 2^-27 that
  // they start within a scan's messages of each other.
  int64_t first[2] = {-1, -1};
  for (int k = 0; k < 2; ++k) {
    Node publisher(k ? "vellum-b" : "vellum-a", "memq://");
    publisher.Subscribe<scan_request_t>("SEQ_PROBE",
                                        [&](const scan_request_t& m) { first[k] = m.seq; });
    scan_request_t probe{};
    probe.station = kDefaultStation;
    publisher.Publish("SEQ_PROBE", &probe);
    for (int t = 0; t < 10 && first[k] < 0; ++t) publisher.lcm().handleTimeout(10);
  }
  ASSERT_GE(first[0], 0);
  ASSERT_GE(first[1], 0);
  EXPECT_GT(std::llabs(first[0] - first[1]), int64_t{1} << 21) << first[0] << " " << first[1];
}

// A product whose sender starts it over before it is whole (a daemon restarted mid-send, the scan
// sent again) is built from the new send alone: the first send's chunks are dropped with an
// error, never mixed in. Two textures of one scan that differ in every row show it.
TEST(Assembler, AProductSentAgainMidwayIsBuiltFromTheNewSendAlone) {
  Node node("vellum-unit", "memq://");
  std::vector<status_t> statuses;
  node.Subscribe<status_t>("STATUS_UNIT", [&](const status_t& m) { statuses.push_back(m); });
  std::mutex mutex;
  std::vector<cv::Mat> products;
  Assembler<texture_t, cv::Mat> assembler(
      &node, "TEXTURE", [](const texture_t& m, cv::Mat* texture) { return AddChunk(m, texture); },
      [&](int64_t, cv::Mat* texture, const texture_t&) {
        const std::lock_guard<std::mutex> lock(mutex);
        products.push_back(texture->clone());
      });
  const cv::Mat first(1200, 1600, CV_8UC3, cv::Scalar::all(40)),
      again(1200, 1600, CV_8UC3, cv::Scalar::all(200));
  std::vector<texture_t> a = TextureMessages(9, first), b = TextureMessages(9, again);
  ASSERT_GE(a.size(), 3u);
  int64_t seq = 0;
  auto send = [&](texture_t m) {
    m.station = kDefaultStation;
    m.seq = seq++;
    node.lcm().publish("TEXTURE", &m);
  };
  send(a[0]);  // The first send stops after two chunks...
  send(a[1]);
  for (const texture_t& m : b) send(m);  // ...and the scan is sent again, whole.
  for (int k = 0; k < 10; ++k) node.lcm().handleTimeout(10);
  while (node.Pending() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  for (int k = 0; k < 10; ++k) node.lcm().handleTimeout(10);
  const std::lock_guard<std::mutex> lock(mutex);
  ASSERT_EQ(products.size(), 1u);
  EXPECT_EQ(cv::norm(products[0], again, cv::NORM_INF), 0.0) << "chunks of both sends mixed";
  ASSERT_FALSE(statuses.empty());
  EXPECT_NE(statuses.back().last_error.find("scan 9: TEXTURE incomplete"), std::string::npos)
      << statuses.back().last_error;
  EXPECT_NE(statuses.back().last_error.find("sent again"), std::string::npos)
      << statuses.back().last_error;
}

// A texture of random pixels (a chunk put in the wrong place shows), 8-bit colour.
cv::Mat RandomTexture(cv::Size size = {1600, 1200}) {
  cv::Mat texture(size, CV_8UC3);
  cv::randu(texture, cv::Scalar::all(0), cv::Scalar::all(256));
  return texture;
}

// A product as a test keeps it: its own pixels, which the receiver's next product cannot change.
cv::Mat Copied(const cv::Mat& image) { return image.clone(); }
using PointsAndAmplitude = std::pair<cv::Mat, cv::Mat>;
PointsAndAmplitude Copied(const PointsAndAmplitude& map) {
  return {map.first.clone(), map.second.clone()};
}

// A daemon receiving `channel`'s chunks on `bus` with `add` (asking again after 1 s, giving up
// after 10 s, by a clock the test steps): the products it made whole, and its statuses.
template <class Msg, class Product>
struct ChunkReceiver {
  ChunkReceiver(lcm::LCM* bus, const std::string& channel,
                typename Assembler<Msg, Product>::AddFn add)
      : node("vellum-unit", bus, &clock),
        assembler(
            &node, channel, std::move(add),
            [this](int64_t, Product* product, const Msg&) {
              const std::lock_guard<std::mutex> lock(mutex);
              products.push_back(Copied(*product));
            },
            /*timeout_s=*/10, /*ask_after_s=*/1) {
    node.Subscribe<status_t>("STATUS_UNIT", [this](const status_t& m) { statuses.push_back(m); });
  }
  // Handles the bus and ticks until a product is whole or `seconds` have passed on the clock,
  // which moves a quarter of a second whenever the bus and the worker are quiet (so that what
  // was asked again comes before the next ask, however slow the machine); the products.
  std::vector<Product> TickUntilWhole(lcm::LCM* bus, double seconds = 30) {
    const Clock::time_point end = clock.Now() + Seconds(seconds);
    while (Products().empty() && clock.Now() < end) {
      const int handled = bus->handleTimeout(10);
      assembler.Tick();
      node.Drain();
      if (handled == 0) clock.Advance(0.25);
    }
    node.Drain();
    return Products();
  }
  // Handles the bus and the worker until `done` (at most 3000 rounds), the clock standing still.
  void HandleUntil(lcm::LCM* bus, const std::function<bool()>& done) {
    for (int round = 0; round < 3000 && !done(); ++round) {
      bus->handleTimeout(10);
      node.Drain();
    }
  }
  std::vector<Product> Products() {
    const std::lock_guard<std::mutex> lock(mutex);
    return products;
  }
  // The errors on the node's status, asked for now ("asked by the test"): none is -1.
  int64_t ErrorsNow(lcm::LCM* bus) {
    const size_t before = statuses.size();
    node.SetState("idle", 0, "asked by the test");
    for (int round = 0; round < 3000 && statuses.size() == before; ++round) bus->handleTimeout(10);
    return statuses.size() == before ? -1 : statuses.back().errors;
  }
  std::string LastError() const { return statuses.empty() ? "" : statuses.back().last_error; }

  SteppedClock clock;
  std::mutex mutex;
  std::vector<Product> products;   // Guarded by mutex (the worker adds).
  std::vector<status_t> statuses;  // The node's, as heard on the bus (the test's thread).
  Node node;
  Assembler<Msg, Product> assembler;
};

struct TextureReceiver : ChunkReceiver<texture_t, cv::Mat> {
  explicit TextureReceiver(lcm::LCM* bus)
      : ChunkReceiver(bus, "TEXTURE",
                      [](const texture_t& m, cv::Mat* image) { return AddChunk(m, image); }) {}
};

// Chunks the bus lost (a loaded machine, a receiver paused) are asked again on RESEND and sent
// again byte for byte by the publisher that holds them: the product is whole and the same, the
// loss and the recovery are counted. The receiver starts listening after the send and is then
// given two of the chunks, as a receiver whose buffer overflowed would have them.
TEST(Assembler, ChunksTheBusLostAreAskedAgainAndTheProductIsRecovered) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const cv::Mat texture = RandomTexture();
  std::vector<texture_t> chunks = TextureMessages(9, texture);
  ASSERT_GE(chunks.size(), 4u);
  sender.PublishChunks("TEXTURE", &chunks);  // No one listens yet: every chunk is lost.
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);

  TextureReceiver r(&bus);
  bus.publish("TEXTURE", &chunks[0]);  // Two chunks came through, as sent (their seq too).
  bus.publish("TEXTURE", &chunks[2]);
  const std::vector<cv::Mat> products = r.TickUntilWhole(&bus);
  ASSERT_EQ(products.size(), 1u) << "not recovered";
  EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0);
  EXPECT_EQ(r.node.Counter("products recovered"), 1);
  EXPECT_EQ(r.node.Counter("products lost"), 0);
  EXPECT_GE(r.node.Counter("chunks asked again"), static_cast<int64_t>(chunks.size()) - 2);
  EXPECT_GE(sender.Counter("chunks sent again"), static_cast<int64_t>(chunks.size()) - 2);
  // The gap between the two chunks that came is a loss; the chunks sent again are not.
  EXPECT_EQ(r.node.Counter("lost messages"), 1);
}

// A product's last chunk come with one before it missing: the missing one is asked again at once,
// with the receiver's clock standing still (no second of quiet waited for), and the loss, once
// recovered, is no error on the receiver's status: an operator is not told of a scan that went
// well. Random texture, so a chunk put in the wrong place shows.
TEST(Assembler, TheLastChunkComingWithOneMissingAsksForItAtOnceAndTheRecoveredLossIsNoError) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const cv::Mat texture = RandomTexture();
  std::vector<texture_t> chunks = TextureMessages(9, texture);
  ASSERT_GE(chunks.size(), 3u);
  sender.PublishChunks("TEXTURE", &chunks);  // Held by the sender; no one listens yet.
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);

  TextureReceiver r(&bus);
  const Clock::time_point start = r.clock.Now();
  for (size_t i = 0; i < chunks.size(); ++i) {
    if (i != 1) bus.publish("TEXTURE", &chunks[i]);  // Chunk 1 lost.
  }
  r.HandleUntil(&bus, [&] { return !r.Products().empty(); });
  const std::vector<cv::Mat> products = r.Products();
  ASSERT_EQ(products.size(), 1u) << "not recovered without the clock moving";
  EXPECT_EQ(r.clock.Now(), start);
  EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0);
  EXPECT_EQ(r.node.Counter("lost messages"), 1);
  EXPECT_EQ(r.node.Counter("chunks asked again"), 1);
  EXPECT_EQ(r.node.Counter("products recovered"), 1);
  // Chunks sent again for another receiver's ask are heard by this one too: dropped, the
  // product not begun again nor asked for.
  bus.publish("TEXTURE", &chunks[0]);
  bus.publish("TEXTURE", &chunks[1]);
  r.HandleUntil(&bus, [&] { return r.node.Counter("chunks heard again") >= 2; });
  EXPECT_EQ(r.node.Counter("chunks heard again"), 2);
  r.clock.Advance(5);  // Long past a second of quiet: nothing is being built, nothing asked.
  for (int k = 0; k < 5; ++k) {
    r.assembler.Tick();
    bus.handleTimeout(10);
    r.node.Drain();
  }
  EXPECT_EQ(r.node.Counter("chunks asked again"), 1);
  EXPECT_EQ(r.Products().size(), 1u);
  EXPECT_EQ(r.ErrorsNow(&bus), 0) << r.LastError();
}

// A product's last chunk lost: nothing comes after it to show the loss but its sender's
// announcement on SCAN_PROGRESS that the product went. The missing chunk is asked for when that
// comes, with the receiver's clock standing still (no second of quiet waited for), and the
// product is recovered with no error.
TEST(Assembler, ALostLastChunkIsAskedForWhenItsSenderAnnouncesTheProductSent) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const cv::Mat texture = RandomTexture();
  std::vector<texture_t> chunks = TextureMessages(9, texture);
  ASSERT_GE(chunks.size(), 2u);
  sender.PublishChunks("TEXTURE", &chunks);  // Held by the sender; no one listens yet.
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);

  TextureReceiver r(&bus);
  r.assembler.AwaitAnnounced("TEXTURE");
  const Clock::time_point start = r.clock.Now();
  for (size_t i = 0; i + 1 < chunks.size(); ++i) bus.publish("TEXTURE", &chunks[i]);
  AnnounceHandedOn(&sender, 9, "TEXTURE");  // The last chunk lost on the way.
  r.HandleUntil(&bus, [&] { return !r.Products().empty(); });
  const std::vector<cv::Mat> products = r.Products();
  ASSERT_EQ(products.size(), 1u) << "not recovered without the clock moving";
  EXPECT_EQ(r.clock.Now(), start);
  EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0);
  EXPECT_EQ(r.node.Counter("chunks asked again"), 1);
  EXPECT_EQ(r.node.Counter("products recovered"), 1);
  // Announced again (a supervisor's start): the product is whole, nothing is asked.
  AnnounceHandedOn(&sender, 9, "TEXTURE");
  for (int k = 0; k < 5; ++k) {
    bus.handleTimeout(10);
    r.node.Drain();
  }
  EXPECT_EQ(r.node.Counter("chunks asked again"), 1);
  EXPECT_EQ(r.node.Counter("products asked again"), 0);
  EXPECT_EQ(r.ErrorsNow(&bus), 0) << r.LastError();
}

// A new send of a product comes while this receiver is asking for a chunk of the first (its
// sender restarted, the scan sent again): a chunk it has, with a seq of its own, is the new send,
// not the first one's chunk late. The product is built from the new send alone, never from two.
TEST(Assembler, ANewSendWhileAskingForALostChunkIsBuiltAloneNotMixedWithTheFirst) {
  lcm::LCM bus("memq://");
  const cv::Mat first = RandomTexture(), again = RandomTexture();
  std::vector<texture_t> a = TextureMessages(9, first), b = TextureMessages(9, again);
  ASSERT_GE(a.size(), 3u);
  ASSERT_EQ(a.size(), b.size());
  TextureReceiver r(&bus);
  for (size_t i = 0; i < a.size(); ++i) {
    a[i].station = b[i].station = kDefaultStation;
    a[i].seq = 100 + static_cast<int64_t>(i);
    b[i].seq = 200 + static_cast<int64_t>(i);
    if (i != 1) bus.publish("TEXTURE", &a[i]);  // Chunk 1 of the first send lost: asked for.
  }
  r.HandleUntil(&bus, [&] { return r.node.Counter("chunks asked again") >= 1; });
  ASSERT_EQ(r.node.Counter("chunks asked again"), 1);
  for (const texture_t& m : b) bus.publish("TEXTURE", &m);  // The new send, whole.
  const std::vector<cv::Mat> products = r.TickUntilWhole(&bus);
  ASSERT_EQ(products.size(), 1u);
  EXPECT_EQ(cv::norm(products[0], again, cv::NORM_INF), 0.0) << "chunks of both sends mixed";
}

// A point map sent as its chunks are made (PublishChunks of a ChunkMaker: each chunk filled into
// one message, its arrays reused) arrives bit for bit, NaNs and amplitude too: each chunk takes
// its own rows and no more (the last one is shorter than the rest). A receiver that missed it
// all asks for it whole and is sent the held chunks, as sent.
TEST(Assembler, APointMapSentAsItsChunksAreMadeArrivesBitForBitAndIsSentAgainAsSent) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  cv::Mat points(1201, 1600, CV_32FC3), amplitude(1201, 1600, CV_32F);
  cv::randu(points, cv::Scalar::all(-300), cv::Scalar::all(300));
  cv::randu(amplitude, 0, 127.5);
  points(cv::Rect(40, 30, 200, 100))
      .setTo(cv::Scalar::all(std::numeric_limits<float>::quiet_NaN()));
  const ChunkMaker<point_cloud_t> maker = PointCloudChunks(5, points, amplitude, ScanContext(), {});
  ASSERT_GE(maker.count, 3);
  point_cloud_t first{}, last{};
  maker.make(0, &first);
  maker.make(maker.count - 1, &last);
  ASSERT_LT(last.row_count, first.row_count) << "the test wants a shorter last chunk";

  struct MapReceiver : ChunkReceiver<point_cloud_t, PointsAndAmplitude> {
    explicit MapReceiver(lcm::LCM* bus)
        : ChunkReceiver(bus, "POINT_CLOUD", [](const point_cloud_t& m, PointsAndAmplitude* map) {
            return AddChunk(m, &map->first, &map->second);
          }) {}
  };
  MapReceiver on_time(&bus);
  ASSERT_TRUE(sender.PublishChunks("POINT_CLOUD", maker).ok());
  std::vector<PointsAndAmplitude> maps = on_time.TickUntilWhole(&bus);
  ASSERT_EQ(maps.size(), 1u);
  EXPECT_TRUE(SameBits(maps[0].first, points));
  EXPECT_TRUE(SameBits(maps[0].second, amplitude));
  EXPECT_EQ(on_time.node.Counter("chunks asked again"), 0);

  MapReceiver late(&bus);
  late.assembler.AwaitAnnounced("POINT_CLOUD");
  AnnounceHandedOn(&sender, 5, "POINT_CLOUD");
  maps = late.TickUntilWhole(&bus);
  ASSERT_EQ(maps.size(), 1u) << "not sent again";
  EXPECT_TRUE(SameBits(maps[0].first, points));
  EXPECT_TRUE(SameBits(maps[0].second, amplitude));
  EXPECT_EQ(sender.Counter("chunks sent again"), maker.count);
}

// A chunk heard twice with one seq while its product is being built (sent again for another
// receiver) is that chunk again, not the product started over by its sender: the product is
// made once, whole, with no error.
TEST(Assembler, AChunkSentAgainForAnotherReceiverMidProductIsNotTakenForANewSend) {
  lcm::LCM bus("memq://");
  const cv::Mat texture = RandomTexture();
  std::vector<texture_t> chunks = TextureMessages(9, texture);
  ASSERT_GE(chunks.size(), 3u);
  for (size_t i = 0; i < chunks.size(); ++i) {
    chunks[i].station = kDefaultStation;
    chunks[i].seq = 500 + static_cast<int64_t>(i);
  }
  TextureReceiver r(&bus);
  bus.publish("TEXTURE", &chunks[0]);
  bus.publish("TEXTURE", &chunks[1]);
  bus.publish("TEXTURE", &chunks[0]);  // Again, for someone else.
  for (size_t i = 2; i < chunks.size(); ++i) bus.publish("TEXTURE", &chunks[i]);
  const std::vector<cv::Mat> products = r.TickUntilWhole(&bus);
  ASSERT_EQ(products.size(), 1u);
  EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0);
  EXPECT_EQ(r.node.Counter("chunks heard again"), 1);
  EXPECT_EQ(r.node.Counter("chunks asked again"), 0);
  EXPECT_EQ(r.ErrorsNow(&bus), 0) << r.LastError();
}

// A sender's work before its last chunk (its files put on disk while the others travel) runs
// when every other chunk has gone and before the last: no receiver has the product whole
// before it is done. When it fails, the last chunk never goes and nothing is held, so the
// product is never whole anywhere: the receiver asks again, no one answers, and it gives up.
TEST(Assembler, TheWorkBeforeTheLastChunkRunsBeforeItAndWhenItFailsTheProductNeverCompletes) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const cv::Mat texture = RandomTexture();
  std::vector<texture_t> chunks = TextureMessages(16, texture);
  ASSERT_GE(chunks.size(), 3u);
  TextureReceiver r(&bus);
  int chunks_seen = 0;
  r.node.Subscribe<texture_t>("TEXTURE", [&](const texture_t&) { ++chunks_seen; });
  auto handle_all = [&] {
    while (bus.handleTimeout(0) > 0) {
    }
  };
  int seen_before_last = -1;
  Status s = sender.PublishChunks("TEXTURE", &chunks, [&] {
    handle_all();
    seen_before_last = chunks_seen;
    r.node.Drain();
    EXPECT_TRUE(r.Products().empty()) << "whole before the sender's work was done";
    return Status::Ok();
  });
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(seen_before_last, static_cast<int>(chunks.size()) - 1);
  ASSERT_EQ(r.TickUntilWhole(&bus).size(), 1u);
  EXPECT_EQ(cv::norm(r.Products()[0], texture, cv::NORM_INF), 0.0);

  // Failing: the last chunk stays here, and no one can send it again.
  std::vector<texture_t> failing = TextureMessages(17, texture);
  chunks_seen = 0;
  s = sender.PublishChunks("TEXTURE", &failing, [] { return Status::Error("disk full"); });
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "disk full");
  handle_all();
  EXPECT_EQ(chunks_seen, static_cast<int>(failing.size()) - 1);
  for (int k = 0; k < 80; ++k) {  // 20 s on the receiver's clock: past its 10 s timeout.
    handle_all();
    r.assembler.Tick();
    r.node.Drain();
    r.clock.Advance(0.25);
  }
  EXPECT_EQ(r.Products().size(), 1u) << "the failed product came whole";
  EXPECT_GE(r.node.Counter("chunks asked again"), 1);
  EXPECT_EQ(sender.Counter("chunks sent again"), 0);
  EXPECT_EQ(r.node.Counter("products lost"), 1);
}

// A product sent once the oldest held ones are let go is encoded into their buffers (their
// pages already in memory): every product, larger or smaller than the one before, comes whole
// and as sent, and so do its chunks sent again from those buffers.
TEST(Assembler, ProductsEncodedIntoTheBuffersOfOnesLetGoComeAsSent) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const std::vector<cv::Size> sizes = {{800, 600},  {800, 600}, {800, 600},
                                       {1200, 900}, {640, 480}, {800, 600}};
  std::vector<cv::Mat> sent;
  for (size_t k = 0; k < sizes.size(); ++k) {
    const cv::Mat texture = RandomTexture(sizes[k]);
    sent.push_back(texture);
    std::vector<texture_t> chunks = TextureMessages(static_cast<int64_t>(20 + k), texture);
    TextureReceiver r(&bus);
    sender.PublishChunks("TEXTURE", &chunks);
    const std::vector<cv::Mat> products = r.TickUntilWhole(&bus);
    ASSERT_EQ(products.size(), 1u) << "product " << k;
    EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0) << "product " << k;
  }
  EXPECT_GT(sender.Counter("chunk buffers reused"), 0);
  // The newest, held in reused buffers, asked again whole by a receiver that missed it.
  TextureReceiver late(&bus);
  late.assembler.AwaitAnnounced("TEXTURE");
  AnnounceHandedOn(&sender, 25, "TEXTURE");
  const std::vector<cv::Mat> again = late.TickUntilWhole(&bus);
  ASSERT_EQ(again.size(), 1u) << "not sent again";
  EXPECT_EQ(cv::norm(again[0], sent.back(), cv::NORM_INF), 0.0);
}

// A product of which no chunk came (the bus lost it all) is known by its sender's announcement
// on SCAN_PROGRESS: it is asked again whole and comes, as sent.
TEST(Assembler, AProductAnnouncedButLostWholeIsAskedAgainWhole) {
  lcm::LCM bus("memq://");
  Node sender("vellum-sender", &bus);
  sender.SetPace(1e12);
  const cv::Mat texture = RandomTexture({800, 600});
  std::vector<texture_t> chunks = TextureMessages(12, texture);
  sender.PublishChunks("TEXTURE", &chunks);  // No one listens: lost whole.
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);

  TextureReceiver r(&bus);
  r.assembler.AwaitAnnounced("TEXTURE");
  AnnounceHandedOn(&sender, 12, "TEXTURE");
  const std::vector<cv::Mat> products = r.TickUntilWhole(&bus);
  ASSERT_EQ(products.size(), 1u) << "not recovered";
  EXPECT_EQ(cv::norm(products[0], texture, cv::NORM_INF), 0.0);
  EXPECT_GE(r.node.Counter("products asked again"), 1);
  EXPECT_EQ(r.node.Counter("products recovered"), 1);
  EXPECT_EQ(sender.Counter("chunks sent again"), static_cast<int64_t>(chunks.size()));
}

// What no one can send again (its sender forgot it, or is gone) is given up after the timeout
// by the receiver's clock, with the chunks it missed and the times it asked named, and counted
// as lost: a product whose chunks stopped, and a product announced of which none came. Before
// the timeout, neither is given up, however long the machine took to get there.
TEST(Assembler, WhatNoOneSendsAgainIsGivenUpAfterTheTimeoutNamingWhatIsMissing) {
  lcm::LCM bus("memq://");
  cv::Mat texture(1200, 1600, CV_8UC3, cv::Scalar(1, 2, 3));
  std::vector<texture_t> chunks = TextureMessages(14, texture);
  ASSERT_GE(chunks.size(), 3u);
  TextureReceiver r(&bus);
  r.assembler.AwaitAnnounced("TEXTURE");
  chunks[0].station = kDefaultStation;
  bus.publish("TEXTURE", &chunks[0]);  // One chunk of scan 14; no sender holds it.
  EXPECT_TRUE(r.TickUntilWhole(&bus, 9.5).empty());
  EXPECT_EQ(r.node.Counter(counter::kProductsLost), 0) << r.LastError();
  // Asked again about every second (each ask waits a second, the clock moves in quarters).
  EXPECT_GE(r.node.Counter("chunks asked again"), 6 * static_cast<int64_t>(chunks.size() - 1));
  EXPECT_TRUE(r.TickUntilWhole(&bus, 1).empty());
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);
  EXPECT_EQ(r.node.Counter(counter::kProductsLost), 1);
  EXPECT_NE(r.LastError().find("scan 14: TEXTURE incomplete (chunks 1, "), std::string::npos)
      << r.LastError();
  EXPECT_NE(r.LastError().find("after 10 s, asked again"), std::string::npos) << r.LastError();

  // Scan 15 announced by its sender; not a chunk comes.
  Node sender("vellum-sender", &bus);
  AnnounceHandedOn(&sender, 15, "TEXTURE");
  EXPECT_TRUE(r.TickUntilWhole(&bus, 9.5).empty());
  EXPECT_EQ(r.node.Counter(counter::kProductsLost), 1) << r.LastError();
  EXPECT_GE(r.node.Counter("products asked again"), 6);
  EXPECT_TRUE(r.TickUntilWhole(&bus, 1).empty());
  for (int k = 0; k < 10; ++k) bus.handleTimeout(1);
  EXPECT_EQ(r.node.Counter(counter::kProductsLost), 2);
  EXPECT_NE(r.LastError().find("scan 15: TEXTURE announced by its sender and never came"),
            std::string::npos)
      << r.LastError();
}

// A hung job on the worker (a stage that never returns) is reported as stuck and
// systemd's watchdog is no longer fed, so systemd restarts the daemon; it is fed again once the
// job ends. A stop while a job hangs returns after the stop grace instead of waiting forever.
TEST(Node, AHungJobStarvesTheWatchdogAndAStopDoesNotWaitForItForever) {
  // systemd's side of the notify protocol: a datagram socket named by $NOTIFY_SOCKET.
  const std::string path =
      (fs::temp_directory_path() / ("vellum_notify_" + std::to_string(getpid()))).string();
  ::unlink(path.c_str());
  const int sock = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(sock, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strcpy(addr.sun_path, path.c_str());
  ASSERT_EQ(bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  setenv("NOTIFY_SOCKET", path.c_str(), 1);
  // Watchdog pings received; waits up to timeout_s for one when `wait`.
  auto pings = [&](bool wait) {
    int n = 0;
    for (;;) {
      pollfd p{sock, POLLIN, 0};
      if (poll(&p, 1, wait && n == 0 ? 30000 : 0) <= 0) return n;
      char buf[256];
      const ssize_t len = recv(sock, buf, sizeof(buf), 0);
      if (len > 0 &&
          std::string(buf, static_cast<size_t>(len)).find("WATCHDOG=1") != std::string::npos) {
        ++n;
      }
    }
  };

  Node node("vellum-unit", "memq://");
  node.SetWorkLimits(/*stuck_after_s=*/0.3, /*stop_grace_s=*/0.5);
  std::mutex mutex;
  std::vector<status_t> statuses;
  node.Subscribe<status_t>("STATUS_UNIT", [&](const status_t& m) {
    std::lock_guard<std::mutex> lock(mutex);
    statuses.push_back(m);
  });
  auto count_status = [&](const std::string& state) {
    std::lock_guard<std::mutex> lock(mutex);
    return std::count_if(statuses.begin(), statuses.end(),
                         [&](const status_t& m) { return m.state == state; });
  };
  auto wait_for = [&](const std::function<bool()>& done) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!done()) {
      if (std::chrono::steady_clock::now() > end) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
  };
  std::atomic<bool> release{false};
  auto hang = [&] {
    while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  };
  int code = -1;
  std::thread runner([&] { code = node.Run(); });
  EXPECT_GE(pings(true), 1) << "no watchdog ping while healthy";
  node.Post(hang, "a stage that never returns");
  ASSERT_TRUE(wait_for([&] { return count_status("stuck") >= 1; }));
  {
    std::lock_guard<std::mutex> lock(mutex);
    const status_t& stuck = statuses.back();
    EXPECT_NE(stuck.last_error.find("stuck: a stage that never returns has run for"),
              std::string::npos)
        << stuck.last_error;
  }
  pings(false);  // Those sent before it was stuck.
  // Two heartbeats later, still stuck: not one ping since.
  const auto seen = count_status("stuck");
  ASSERT_TRUE(wait_for([&] { return count_status("stuck") >= seen + 2; }));
  EXPECT_EQ(pings(false), 0) << "the watchdog was fed while the worker hung";
  EXPECT_EQ(node.Counter("stuck"), 1);
  release = true;
  EXPECT_GE(pings(true), 1) << "the watchdog was not fed again once the job ended";
  // A stop while a job hangs: Run gives up after the grace and says so.
  release = false;
  node.Post(hang, "another hung stage");
  node.Stop();
  runner.join();
  EXPECT_EQ(code, 1);
  EXPECT_TRUE(node.Abandoned());
  release = true;
  while (node.Pending() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  unsetenv("NOTIFY_SOCKET");
  close(sock);
  ::unlink(path.c_str());
}

}  // namespace
}  // namespace vellum::station
