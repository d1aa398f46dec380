// The decoder's node on an in-process bus: a scan's captures are recorded as they arrive and
// the whole scan is sent down the chain (TEXTURE, CORRESPONDENCE with the decode report,
// SCAN_PROGRESS); bad captures are reported and the node goes on; an incomplete scan is given
// up after its timeout with the missing captures named, and the next scan is recorded whole.
#include "daemons/decoder/decoder_node.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <stdexcept>

#include "io/calibration_io.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/scan_log.h"
#include "station/testing.h"
#include "vellum/light_t.hpp"
#include "vellum/restored_t.hpp"
#include "vellum/scan_progress_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;
using testing::MemqBus;
using testing::SmallScan;

class DecoderNodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    data_ = testing::TestDir("decoder_node");
    options_.data_dir = data_;
    options_.scan_timeout_s = 1;
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(data_);
  }
  // Publishes SmallScan as scan `id` (SCAN_STARTED, texture first), except pattern `skip`;
  // returns its session.
  int64_t PublishScan(int64_t id, int skip = -2) {
    return testing::PublishScan(bus_.probe(), SmallScan(), id, skip);
  }
  // One capture of SmallScan.
  capture_t Capture(int64_t id, int64_t session, int pattern_index) {
    capture_t c = MakeCapture(SmallScan(), id, pattern_index, NowUtime());
    c.session = session;
    return c;
  }
  void Start(int64_t id, int64_t session) {
    scan_started_t m = MakeScanStarted(SmallScan(), id, session);
    bus_.probe().Publish(channel::kScanStarted, &m);
  }

  // A processing daemon's status, idle, with one counter when `counter` is named.
  static status_t DaemonStatus(const std::string& process, int32_t pid,
                               const std::string& counter = "", int64_t value = 0) {
    status_t m{};
    m.process = process;
    m.pid = pid;
    m.state = "idle";
    if (!counter.empty()) {
      m.counter_names = {counter};
      m.counter_values = {value};
      m.ncounters = 1;
    }
    return m;
  }
  void Publish(status_t m) { bus_.probe().Publish(StatusChannel(m.process), &m); }
  // A processing daemon's heartbeat (a new pid: it restarted).
  void Heartbeat(const std::string& process, int32_t pid) { Publish(DaemonStatus(process, pid)); }
  // How many times scan `id` was sent down the chain.
  static int Sent(const std::vector<correspondence_t>& correspondence, int64_t id) {
    int n = 0;
    for (const correspondence_t& m : correspondence) n += m.scan_id == id && m.chunk_index == 0;
    return n;
  }

  std::string data_;
  DecoderNodeOptions options_;
  MemqBus bus_;
};

TEST_F(DecoderNodeTest, RecordsAScanAndSendsItDownTheChain) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto texture = bus_.Record<texture_t>(channel::kTexture);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishScan(11);
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(progress->back().scan_id, 11);
  EXPECT_EQ(progress->back().process, "vellum-decoder");
  EXPECT_EQ(progress->back().product, "CORRESPONDENCE");

  // The raw folder is a scan directory equal to what was captured, and its log holds it all.
  const ScanFolder folder = ScanFolder::For(data_, 11);
  Scan recorded;
  ASSERT_TRUE(ReadScan(folder.raw(), &recorded).ok());
  const Scan& scan = SmallScan();
  ASSERT_EQ(recorded.frames.size(), scan.frames.size());
  EXPECT_EQ(cv::norm(recorded.texture, scan.texture, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(recorded.frames[5], scan.frames[5], cv::NORM_INF), 0);
  Scan logged;
  bool has_calibration = true;
  calibration_t calibration;
  int64_t id = 0;
  ASSERT_TRUE(ReadScanLog(folder.log(), 11, &logged, &has_calibration, &calibration, &id).ok());
  EXPECT_FALSE(has_calibration);
  EXPECT_TRUE(fs::exists(folder.pending())) << "in the supervisor's ledger until RESTORED";
  // Every raw file was hashed as it was written (the manifest need not read raw/ again after
  // the last frame), each hash the file's own.
  std::ifstream recorded_hashes(fs::path(folder.root) / kRecordedHashesName);
  std::set<std::string> hashed;
  for (std::string hex, size, mtime, rel; recorded_hashes >> hex >> size >> mtime >> rel;) {
    std::string real;
    ASSERT_TRUE(Sha256OfFile((fs::path(folder.root) / rel).string(), &real).ok()) << rel;
    EXPECT_EQ(hex, real) << rel;
    hashed.insert(rel);
  }
  for (const auto& entry : fs::directory_iterator(folder.raw())) {
    const std::string rel = "raw/" + entry.path().filename().string();
    EXPECT_TRUE(hashed.count(rel)) << rel << " was not hashed as it was recorded";
  }

  // The texture went whole, and the correspondences with the decode stage's report.
  cv::Mat sent_texture;
  for (const texture_t& m : *texture) ASSERT_TRUE(AddChunk(m, &sent_texture).ok());
  EXPECT_EQ(cv::norm(sent_texture, scan.texture, cv::NORM_INF), 0);
  ASSERT_FALSE(correspondence->empty());
  DecodeResult decoded;
  cv::Size projector;
  for (const correspondence_t& m : *correspondence) {
    ASSERT_TRUE(AddChunk(m, &decoded, &projector).ok());
  }
  EXPECT_EQ(projector, scan.sequence.projector_size);
  EXPECT_GT(cv::countNonZero(decoded.valid), scan.camera_size.area() / 4);
  std::vector<StageReport> stages;
  ASSERT_TRUE(FromMessages(correspondence->back().stages, &stages).ok());
  ASSERT_EQ(stages.size(), 1u);
  EXPECT_EQ(stages[0].stage, "decode");
  EXPECT_EQ(node.Counter("scans recorded"), 1);
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans decoded") == 1; }));  // Counted after it is announced.
  // Each capture was taken up as it came (the station's own sequence), none held to the end.
  EXPECT_EQ(node.Counter("scans decoded as captured"), 1);
  EXPECT_EQ(node.Counter("scans decoded from their folder"), 0);
}

// The texture goes on as soon as it is recorded, before any frame (at 24 MP its 72 MB take
// 0.7 s on the bus, which then no longer falls after the last frame), and only once.
TEST_F(DecoderNodeTest, TheTextureGoesOnAsItIsRecordedAndOnlyOnce) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto texture = bus_.Record<texture_t>(channel::kTexture);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  const int64_t session = NewSession();
  Start(13, session);
  capture_t c = Capture(13, session, -1);
  bus_.probe().Publish(channel::kCapture, &c);
  ASSERT_TRUE(bus_.RunUntil([&] {
    return !texture->empty() && static_cast<int>(texture->size()) == texture->front().chunk_count;
  }));
  cv::Mat sent;
  for (const texture_t& m : *texture) ASSERT_TRUE(AddChunk(m, &sent).ok());
  EXPECT_EQ(cv::norm(sent, SmallScan().texture, cv::NORM_INF), 0);
  EXPECT_EQ(texture->front().scan_id, 13);
  const size_t chunks = texture->size();
  for (int k = 0; k < static_cast<int>(SmallScan().frames.size()); ++k) {
    c = Capture(13, session, k);
    bus_.probe().Publish(channel::kCapture, &c);
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(progress->back().product, "CORRESPONDENCE");
  EXPECT_EQ(texture->size(), chunks) << "the texture was sent again with the scan";
}

// The operator's leaf hint (drawn in the viewer: fractions of the camera's view on the bus)
// reaches scan.yaml, the scan's context and the decode stage's report in the camera's pixels,
// exactly, and the log keeps it (a replay or an export finds the same); so does what the operator
// says the object is.
TEST_F(DecoderNodeTest, TheOperatorsLeafHintIsRecordedInCameraPixels) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  Scan hinted = SmallScan();
  const cv::Size camera = hinted.camera_size;
  // An odd region, off the view's centre: a mapping that swaps x and y or rounds to a coarse
  // grid shows.
  hinted.leaf_hint =
      cv::Rect(camera.width / 7, camera.height / 3 + 1, camera.width / 5 + 3, camera.height / 4);
  hinted.object = ObjectKind::kBook;
  testing::PublishScan(bus_.probe(), hinted, 12);
  ASSERT_TRUE(bus_.RunUntil([&] { return !correspondence->empty(); }));
  const ScanFolder folder = ScanFolder::For(data_, 12);
  Scan recorded;
  ASSERT_TRUE(ReadScanHeader(folder.raw(), &recorded).ok());
  EXPECT_EQ(recorded.leaf_hint, hinted.leaf_hint);
  EXPECT_EQ(recorded.object, ObjectKind::kBook);
  // It travels down the chain in the scan's context, as a type, and the report records it.
  ScanContext context;
  ASSERT_TRUE(FromMessage(correspondence->back().context, &context).ok());
  EXPECT_EQ(context.leaf_hint, hinted.leaf_hint);
  EXPECT_EQ(context.object, ObjectKind::kBook);
  std::vector<StageReport> stages;
  ASSERT_TRUE(FromMessages(correspondence->back().stages, &stages).ok());
  const ReportValue* recorded_hint = FindValue(stages, "operator", "leaf_hint");
  ASSERT_NE(recorded_hint, nullptr);
  EXPECT_EQ(recorded_hint->text, LeafHintText(hinted.leaf_hint));
  Scan logged;
  bool has_calibration = false;
  calibration_t calibration;
  int64_t id = 0;
  ASSERT_TRUE(ReadScanLog(folder.log(), 12, &logged, &has_calibration, &calibration, &id).ok());
  EXPECT_EQ(logged.leaf_hint, hinted.leaf_hint);
  EXPECT_EQ(logged.object, ObjectKind::kBook);
  // A scan without one has none.
  PublishScan(13);
  ASSERT_TRUE(bus_.RunUntil([&] { return correspondence->back().scan_id == 13; }));
  ASSERT_TRUE(ReadScanHeader(ScanFolder::For(data_, 13).raw(), &recorded).ok());
  EXPECT_TRUE(recorded.leaf_hint.empty());
  EXPECT_EQ(recorded.object, ObjectKind::kAuto);
}

TEST_F(DecoderNodeTest, BadCapturesAreReportedAndTheNodeGoesOn) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.Watch("vellum-decoder");
  Start(21, 7);
  capture_t short_image = Capture(21, 7, 0);
  short_image.image.size = 1000;
  short_image.image.data.resize(1000);
  bus_.probe().Publish(channel::kCapture, &short_image);
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "image data is 1000 bytes"))
      << bus_.Status("vellum-decoder").last_error;
  // A scan with a capture it cannot use is given up at once, and marked so on disk.
  EXPECT_TRUE(fs::exists(ScanFolder::For(data_, 21).failed()));
  capture_t beyond = Capture(21, 7, 1);
  beyond.pattern_index = beyond.pattern_count;  // One past the last pattern.
  bus_.probe().Publish(channel::kCapture, &beyond);
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "pattern_index outside"))
      << bus_.Status("vellum-decoder").last_error;
  EXPECT_EQ(node.Counter("captures refused"), 1);
  // Such captures are refused before the scan's log (counted), as is a projector of 2^30 px.
  capture_t wide = Capture(21, 7, 1);
  wide.projector_width = 1 << 30;
  bus_.probe().Publish(channel::kCapture, &wide);
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "projector size 1073741824x"))
      << bus_.Status("vellum-decoder").last_error;
  EXPECT_EQ(node.Counter("captures refused"), 2);
  capture_t no_scan = Capture(0, 7, 1);
  bus_.probe().Publish(channel::kCapture, &no_scan);
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "scan 0, pattern 1: CAPTURE refused: no scan"))
      << bus_.Status("vellum-decoder").last_error;
  // The node goes on: a whole scan after the bad ones is recorded and decoded.
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishScan(22);
  EXPECT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans decoded") == 1; }));  // Counted after it is announced.
}

TEST_F(DecoderNodeTest, AnIncompleteScanIsGivenUpNamingWhatIsMissingAndTheNextIsWhole) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.AddTick([&] { decoder.Tick(); });
  bus_.Watch("vellum-decoder");
  PublishScan(31, /*skip=*/4);
  const int total = static_cast<int>(SmallScan().frames.size()) + 1;
  // Not given up before its timeout (1 s) has passed on the node's clock...
  bus_.StepFor(0.9);
  EXPECT_EQ(node.Counter("scans failed"), 0) << bus_.Status("vellum-decoder").last_error;
  // ...and given up once it has.
  ASSERT_TRUE(bus_.StepUntil(
      [&] {
        return bus_.Status("vellum-decoder")
                   .last_error.find("scan 31 failed: no capture for 1 s") != std::string::npos;
      },
      0.1, 1))
      << bus_.Status("vellum-decoder").last_error;
  const std::string error = bus_.Status("vellum-decoder").last_error;
  EXPECT_NE(error.find("1 of " + std::to_string(total) + " captures missing (4)"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find(ScanFolder::For(data_, 31).raw()), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(ScanFolder::For(data_, 31).pending()));
  EXPECT_TRUE(fs::exists(ScanFolder::For(data_, 31).failed()));
  EXPECT_EQ(node.Counter("scans failed"), 1);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishScan(32);
  EXPECT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(progress->back().scan_id, 32);
}

// A scan with extra lights. While its projector waits for a light (LIGHT_REQUEST: an
// operator may take minutes) the scan is not given up for its silence; the lights' captures
// complete it, recorded as light_<name>.png and named in scan.yaml. After the lights are turned
// off (LIGHT_REQUEST -1) with a light's capture still missing, the timeout runs again.
TEST_F(DecoderNodeTest, AScanWaitingForALightIsNotGivenUpAndItsLightsAreRecorded) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.AddTick([&] { decoder.Tick(); });
  bus_.Watch("vellum-decoder");
  Scan scan = SmallScan();
  for (const char* name : {"raking-000", "uv"}) {
    ScanLight light;
    light.name = name;
    if (name[0] == 'r') light.direction = cv::Vec3d(0.8, 0, 0.6);
    light.image = cv::Mat(scan.texture.size(), CV_8U, cv::Scalar(name[0] == 'r' ? 90 : 40));
    scan.lights.push_back(light);
  }
  const int patterns = static_cast<int>(scan.frames.size());
  auto publish_scan = [&](int64_t id, int64_t session, int lights) {
    scan_started_t m = MakeScanStarted(scan, id, session);
    bus_.probe().Publish(channel::kScanStarted, &m);
    for (int k = -1; k < patterns + lights; ++k) {
      capture_t c = MakeCapture(scan, id, k, NowUtime());
      c.session = session;
      bus_.probe().Publish(channel::kCapture, &c);
    }
  };
  auto request = [&](int64_t id, int64_t session, int index) {
    light_t r{};
    r.scan_id = id;
    r.session = session;
    r.index = index;
    r.light_count = 2;
    if (index >= 0) r.light = ToMessage(scan.lights[index]);
    bus_.probe().Publish(channel::kLightRequest, &r);
  };
  publish_scan(41, 4141, 0);
  request(41, 4141, 0);
  // A minute, sixty times the decoder's timeout (1 s), in silence: the scan waits for its light.
  bus_.StepFor(60, 1);
  EXPECT_EQ(node.Counter("scans failed"), 0) << bus_.Status("vellum-decoder").last_error;
  for (int k = 0; k < 2; ++k) {
    capture_t c = MakeCapture(scan, 41, patterns + k, NowUtime());
    c.session = 4141;
    bus_.probe().Publish(channel::kCapture, &c);
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("scans recorded") == 1; }))
      << bus_.Status("vellum-decoder").last_error;
  Scan recorded;
  ASSERT_TRUE(ReadScan(ScanFolder::For(data_, 41).raw(), &recorded).ok());
  ASSERT_EQ(recorded.lights.size(), 2u);
  EXPECT_EQ(recorded.lights[0].name, "raking-000");
  EXPECT_TRUE(recorded.lights[0].directed());
  EXPECT_EQ(cv::norm(recorded.lights[1].image, scan.lights[1].image, cv::NORM_INF), 0);
  // The lights off with the second light's capture missing: given up once the timeout has run.
  publish_scan(42, 4242, 1);
  request(42, 4242, 1);
  request(42, 4242, -1);
  ASSERT_TRUE(bus_.StepUntil(
      [&] {
        return bus_.Status("vellum-decoder")
                   .last_error.find("scan 42 failed: no capture for 1 s") != std::string::npos;
      },
      0.1, 2))
      << bus_.Status("vellum-decoder").last_error;
  EXPECT_NE(bus_.Status("vellum-decoder").last_error.find("(light 1)"), std::string::npos)
      << bus_.Status("vellum-decoder").last_error;
}

// The supervisor in the decoder: a restarted daemon (a new pid in its heartbeat) is sent again
// only the scans it held; a scan already past it is not processed twice.
TEST_F(DecoderNodeTest, ARestartedDaemonIsSentAgainOnlyTheScansItHeld) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto heartbeat = [&](const std::string& process, int32_t pid) { Heartbeat(process, pid); };
  auto handed_on = [&](const std::string& process, int64_t id) {
    scan_progress_t m{};
    m.scan_id = id;
    m.process = process;
    m.pid = 1;
    m.product = "x";
    bus_.probe().Publish(channel::kScanProgress, &m);
  };
  auto sent = [&](int64_t id) { return Sent(*correspondence, id); };
  heartbeat("vellum-triangulator", 100);
  heartbeat("vellum-flattener", 200);
  heartbeat("vellum-restorer", 300);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 3; }));
  PublishScan(41);
  ASSERT_TRUE(bus_.RunUntil([&] { return sent(41) == 1; }));
  // Scan 41 went past the triangulator and the flattener: it is at the restorer.
  handed_on("vellum-triangulator", 41);
  handed_on("vellum-flattener", 41);
  heartbeat("vellum-triangulator", 101);  // The triangulator restarts: not its scan.
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("restarts seen") == 1; }));
  EXPECT_EQ(node.Counter("scans sent again"), 0);
  heartbeat("vellum-flattener", 201);  // Nor the flattener's.
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("restarts seen") == 2; }));
  EXPECT_EQ(node.Counter("scans sent again"), 0);
  EXPECT_EQ(sent(41), 1) << "a scan past the restarted daemon was sent again";
  heartbeat("vellum-restorer", 301);  // The restorer held it: sent again, from disk.
  ASSERT_TRUE(bus_.RunUntil([&] { return sent(41) == 2; }));
  EXPECT_EQ(node.Counter("scans sent again"), 1);
  // Decoded as it was captured the first time, read back from its folder the second: the same.
  EXPECT_EQ(node.Counter("scans decoded as captured"), 1);
  EXPECT_EQ(node.Counter("scans decoded from their folder"), 1);
  auto chunks = [&] {
    return std::count_if(correspondence->begin(), correspondence->end(),
                         [](const correspondence_t& m) { return m.scan_id == 41; });
  };
  ASSERT_TRUE(bus_.RunUntil([&] { return chunks() == 2 * correspondence->front().chunk_count; }));
  DecodeResult first, second;
  cv::Size projector;
  int sends = 0;
  for (const correspondence_t& m : *correspondence) {
    if (m.scan_id != 41) continue;
    sends += m.chunk_index == 0;  // A send's chunks follow its first on the in-memory bus.
    ASSERT_TRUE(AddChunk(m, sends == 1 ? &first : &second, &projector).ok());
  }
  ASSERT_FALSE(first.valid.empty());
  ASSERT_FALSE(second.valid.empty());
  EXPECT_EQ(cv::norm(first.valid, second.valid, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(first.projector_x, second.projector_x, cv::NORM_INF, first.valid), 0);
  EXPECT_EQ(PendingAttempts(ScanFolder::For(data_, 41)), 2);
  // Restored: out of the ledger, and never sent again.
  restored_t done{};
  done.scan_id = 41;
  bus_.probe().Publish(channel::kRestored, &done);
  ASSERT_TRUE(bus_.RunUntil([&] { return !fs::exists(ScanFolder::For(data_, 41).pending()); }));
  heartbeat("vellum-restorer", 302);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("restarts seen") == 4; }));
  EXPECT_EQ(sent(41), 2);
}

// The chain is first whole when the last processing daemon is heard (its status may come in
// behind a scan's captures, or be lost on a loaded bus). A scan this process sent is not sent
// again then (it would be flattened and restored beside the first send, into the same folder):
// its last product is announced again, and a daemon that was not listening asks for it again.
TEST_F(DecoderNodeTest, WhenTheChainIsFirstWholeTheScansOnTheirWayAreAnnouncedNotSentAgain) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  auto announced = [&](int64_t id, const std::string& product) {
    return std::count_if(progress->begin(), progress->end(), [&](const scan_progress_t& m) {
      return m.scan_id == id && m.product == product;
    });
  };
  // Scan 51 is sent before any processing daemon is heard; scan 52 once two are, and the
  // triangulator hands it on.
  PublishScan(51);
  ASSERT_TRUE(bus_.RunUntil([&] { return Sent(*correspondence, 51) == 1; }));
  Heartbeat("vellum-triangulator", 100);
  Heartbeat("vellum-flattener", 200);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 2; }));
  PublishScan(52);
  ASSERT_TRUE(bus_.RunUntil([&] { return Sent(*correspondence, 52) == 1; }));
  scan_progress_t handed{};
  handed.scan_id = 52;
  handed.process = "vellum-triangulator";
  handed.pid = 100;
  handed.product = channel::kPointCloud;
  bus_.probe().Publish(channel::kScanProgress, &handed);
  ASSERT_TRUE(bus_.RunUntil([&] { return announced(52, channel::kPointCloud) == 1; }));
  Heartbeat("vellum-restorer", 300);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("products announced again") == 2; }));
  // Each scan's last product again: 51's CORRESPONDENCE (from the decoder), 52's POINT_CLOUD.
  ASSERT_TRUE(bus_.RunUntil([&] {
    return announced(51, channel::kCorrespondence) == 2 && announced(52, channel::kPointCloud) == 2;
  }));
  // A mark published from the decoder's worker after that: every send before it has come.
  auto mark = bus_.Record<scan_progress_t>("TEST_MARK");
  node.Post([&] {
    scan_progress_t m{};
    bus_.probe().Publish("TEST_MARK", &m);
  });
  ASSERT_TRUE(bus_.RunUntil([&] { return !mark->empty(); }));
  EXPECT_EQ(node.Counter("scans sent again"), 0);
  EXPECT_EQ(Sent(*correspondence, 51), 1) << "a scan on its way was sent down the chain again";
  EXPECT_EQ(Sent(*correspondence, 52), 1) << "a scan on its way was sent down the chain again";
  EXPECT_EQ(PendingAttempts(ScanFolder::For(data_, 51)), 1);
  // The triangulator had not heard 51: it asks for the whole product, which the decoder holds.
  resend_request_t ask{};
  ask.process = "vellum-triangulator";
  ask.channel = channel::kCorrespondence;
  ask.scan_id = 51;
  bus_.probe().Publish(channel::kResend, &ask);
  ASSERT_TRUE(bus_.RunUntil([&] { return Sent(*correspondence, 51) == 2; }));
  EXPECT_EQ(PendingAttempts(ScanFolder::For(data_, 51)), 1);  // The same attempt, made whole.
}

// The projector's light (the decoder's amplitude, 4 of CORRESPONDENCE's 13 bytes a pixel) goes
// down the chain only while the restorer wants it for the albedo: sent before a restorer is
// heard, left out once the restorer says it makes no albedo (the rest of the product bit for bit
// the same), and sent again once a restorer started with a flat field says it does.
TEST_F(DecoderNodeTest, TheProjectorsLightGoesDownTheChainOnlyWhileTheRestorerWantsIt) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto restorer = [&](int32_t pid, int64_t wanted) {
    Publish(DaemonStatus("vellum-restorer", pid, counter::kLightWanted, wanted));
  };
  // Scan `id` sent (once, every chunk), as it came: its correspondences and light.
  auto sent = [&](int64_t id, DecodeResult* decoded) {
    EXPECT_TRUE(bus_.RunUntil([&] {
      const auto chunks = std::count_if(correspondence->begin(), correspondence->end(),
                                        [&](const correspondence_t& m) { return m.scan_id == id; });
      return chunks > 0 && chunks == correspondence->back().chunk_count;
    })) << id;
    EXPECT_EQ(Sent(*correspondence, id), 1) << id;
    cv::Size projector;
    for (const correspondence_t& m : *correspondence) {
      if (m.scan_id != id) continue;
      EXPECT_TRUE(AddChunk(m, decoded, &projector).ok()) << id;
    }
  };
  DecodeResult with_light, without, again;
  PublishScan(61);
  sent(61, &with_light);
  EXPECT_EQ(with_light.amplitude.size(), SmallScan().camera_size) << "no restorer heard yet";
  restorer(300, 0);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 1; }));
  PublishScan(62);
  sent(62, &without);
  EXPECT_TRUE(without.amplitude.empty()) << "the light went to a restorer that makes no albedo";
  EXPECT_TRUE(testing::SameBits(without.projector_x, with_light.projector_x));
  EXPECT_TRUE(testing::SameBits(without.projector_y, with_light.projector_y));
  EXPECT_TRUE(testing::SameBits(without.valid, with_light.valid));
  restorer(301, 1);  // Restarted with a flat field.
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("restarts seen") == 1; }));
  PublishScan(63);
  sent(63, &again);
  EXPECT_TRUE(testing::SameBits(again.amplitude, with_light.amplitude));
}

// A scan that loses its daemon twice (a scan that crashes or hangs the restorer each time) is
// parked: marked failed on disk with the reason, out of the ledger, reported, and not sent again
// after another restart of the daemon or of the decoder itself.
TEST_F(DecoderNodeTest, AScanThatLosesItsDaemonTwiceIsParked) {
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto heartbeat = [&](const std::string& process, int32_t pid) { Heartbeat(process, pid); };
  auto sent = [&](int64_t id) { return Sent(*correspondence, id); };
  const ScanFolder folder = ScanFolder::For(data_, 42);
  bus_.Watch("vellum-decoder");
  {
    Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
    DecoderNode decoder(&node, options_);
    heartbeat("vellum-triangulator", 100);
    heartbeat("vellum-flattener", 200);
    heartbeat("vellum-restorer", 300);
    ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 3; }));
    PublishScan(42);
    ASSERT_TRUE(bus_.RunUntil([&] { return sent(42) == 1; }));
    heartbeat("vellum-triangulator", 101);  // It held the scan, and died: sent again.
    ASSERT_TRUE(bus_.RunUntil([&] { return sent(42) == 2; }));
    EXPECT_EQ(PendingAttempts(folder), 2);
    heartbeat("vellum-triangulator", 102);  // Again: parked.
    ASSERT_TRUE(bus_.WaitForError("vellum-decoder", "scan 42 failed and is parked"))
        << bus_.Status("vellum-decoder").last_error;
    const std::string error = bus_.Status("vellum-decoder").last_error;
    EXPECT_NE(error.find("not restored after 2 attempts"), std::string::npos) << error;
    EXPECT_NE(error.find("vellum-triangulator restarted"), std::string::npos) << error;
    EXPECT_NE(error.find(folder.raw()), std::string::npos) << error;
    EXPECT_EQ(node.Counter("scans parked"), 1);
    EXPECT_FALSE(fs::exists(folder.pending()));
    std::ifstream failed(folder.failed());
    const std::string why((std::istreambuf_iterator<char>(failed)), {});
    EXPECT_EQ(why.rfind("parked: not restored after 2 attempts", 0), 0u) << why;
    heartbeat("vellum-triangulator", 103);
    ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("restarts seen") == 3; }));
    EXPECT_EQ(sent(42), 2);
  }
  // The decoder restarts: nothing is pending, so nothing goes down the chain.
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  heartbeat("vellum-triangulator", 104);
  heartbeat("vellum-flattener", 201);
  heartbeat("vellum-restorer", 301);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 3; }));
  EXPECT_EQ(node.Counter("scans sent again"), 0);
  EXPECT_EQ(sent(42), 2);
}

// A daemon that lost a scan's product on the bus (asked again in vain: its "products lost"
// counter rises with the error) does not fail the scan: it is made again from its captures on
// disk. Another error about a scan fails it, as before.
TEST_F(DecoderNodeTest, AScanWhoseProductTheBusLostIsSentAgainAndOtherErrorsFailIt) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto sent = [&](int64_t id) { return Sent(*correspondence, id); };
  auto status = [&](int32_t pid, int64_t error_scan, int64_t error_utime, int64_t lost) {
    status_t m = DaemonStatus("vellum-flattener", pid, counter::kProductsLost, lost);
    m.last_error_scan_id = error_scan;
    m.last_error_utime = error_utime;
    m.last_error = error_scan ? "scan " + std::to_string(error_scan) + ": an error" : "";
    Publish(m);
  };
  Heartbeat("vellum-triangulator", 100);
  status(200, 0, 0, 0);
  Heartbeat("vellum-restorer", 300);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("processing daemons heard") == 3; }));
  PublishScan(43);
  ASSERT_TRUE(bus_.RunUntil([&] { return sent(43) == 1; }));
  status(200, 43, 1000, 1);  // POINT_CLOUD of scan 43 lost on the bus.
  ASSERT_TRUE(bus_.RunUntil([&] { return sent(43) == 2; }));
  EXPECT_EQ(node.Counter("scans sent again"), 1);
  EXPECT_EQ(PendingAttempts(ScanFolder::For(data_, 43)), 2);
  EXPECT_FALSE(fs::exists(ScanFolder::For(data_, 43).failed()));
  PublishScan(44);
  ASSERT_TRUE(bus_.RunUntil([&] { return sent(44) == 1; }));
  status(200, 44, 2000, 1);  // Another error (no leaf found, say): scan 44 fails.
  ASSERT_TRUE(bus_.RunUntil([&] { return fs::exists(ScanFolder::For(data_, 44).failed()); }));
  EXPECT_EQ(sent(44), 1);
  EXPECT_EQ(node.Counter("scans sent again"), 1);
}

// Every byte of every file under `dir`, by relative path.
std::map<std::string, std::string> Snapshot(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file())
      files[fs::relative(e.path(), dir).string()] = testing::ReadBytes(e.path());
  }
  return files;
}

// Scan identity: a capture is recorded only for a scan this station's projector
// started, with its session; a finished scan is never reopened; unknown scans leave no folder.
TEST_F(DecoderNodeTest, RecordsOnlyTheScansItsProjectorStartedAndNeverReopensOne) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.Watch("vellum-decoder");
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  // 300 captures of scans never started: refused, counted, no folder, no disk used.
  for (int k = 0; k < 300; ++k) {
    capture_t c = Capture(1000 + k, 99, k % 4);
    bus_.probe().Publish(channel::kCapture, &c);
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("captures refused (unknown scan)") == 300; }))
      << bus_.Status("vellum-decoder").last_error;
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "no SCAN_STARTED"));
  EXPECT_TRUE(fs::is_empty(data_) ||
              std::none_of(fs::directory_iterator(data_), fs::directory_iterator(),
                           [](const auto& e) { return e.is_directory(); }))
      << "a refused capture made a folder";
  const int64_t session = PublishScan(51);
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  const ScanFolder folder = ScanFolder::For(data_, 51);
  const auto archived = Snapshot(folder.raw());
  // Stale captures of the finished scan, with its session or another, and the scan started
  // again: all refused, the archive unchanged byte for byte, the scan not sent again.
  capture_t stale = Capture(51, session, 3);
  bus_.probe().Publish(channel::kCapture, &stale);
  ASSERT_TRUE(bus_.WaitForError("vellum-decoder", "the scan is over"));
  // Refused captures are not errors of a scan (none is reported against scan 51).
  EXPECT_EQ(bus_.Status("vellum-decoder").last_error_scan_id, 0);
  Start(51, session + 1);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("scans refused") == 1; }));
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "already exists"))
      << bus_.Status("vellum-decoder").last_error;
  capture_t again = Capture(51, session + 1, -1);
  bus_.probe().Publish(channel::kCapture, &again);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("captures refused (scan over)") == 2; }));
  EXPECT_EQ(Snapshot(folder.raw()), archived);
  EXPECT_EQ(node.Counter("scans recorded"), 1);
  EXPECT_EQ(progress->size(), 1u);
  // Another station's scan on the same bus is not this station's: dropped and counted.
  Node other_station("vellum-projector", &bus_.lcm());
  other_station.SetStation("gantry-2");
  testing::PublishScan(other_station, SmallScan(), 52);
  // SCAN_STARTED, the texture and every frame.
  const int64_t messages = 1 + 1 + static_cast<int64_t>(SmallScan().frames.size());
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("from other stations") == messages; }));
  EXPECT_FALSE(fs::exists(ScanFolder::For(data_, 52).root));
}

TEST_F(DecoderNodeTest, ACaptureTwiceOrOfAnotherSessionIsNeverASilentChoice) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.Watch("vellum-decoder");
  // Scan 61 in progress: a capture of another session (another projector, a stale one) is
  // refused and the scan goes on; a second capture of a pattern fails the scan, named.
  Start(61, 1);
  capture_t texture = Capture(61, 1, -1);
  bus_.probe().Publish(channel::kCapture, &texture);
  capture_t other = Capture(61, 2, 0);
  bus_.probe().Publish(channel::kCapture, &other);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("captures refused (other session)") == 1; }));
  capture_t first = Capture(61, 1, 0);
  bus_.probe().Publish(channel::kCapture, &first);
  capture_t second = Capture(61, 1, 0);
  bus_.probe().Publish(channel::kCapture, &second);
  ASSERT_TRUE(
      bus_.WaitForError("vellum-decoder", "scan 61 failed: scan 61, pattern 0: captured twice"))
      << bus_.Status("vellum-decoder").last_error;
  EXPECT_EQ(bus_.Status("vellum-decoder").last_error_scan_id, 61);
  EXPECT_TRUE(fs::exists(ScanFolder::For(data_, 61).failed()));
  // The log holds the texture and the first capture only: it still exports as far as it goes.
  Scan logged;
  bool has_calibration = false;
  calibration_t calibration;
  int64_t id = 0;
  const Status read = ReadScanLog(ScanFolder::For(data_, 61).log(), 61, &logged, &has_calibration,
                                  &calibration, &id);
  EXPECT_NE(read.message().find("incomplete"), std::string::npos) << read.message();
  // A second decoder on the same data folder refuses to start, naming the first.
  Node second_node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  try {
    DecoderNode two(&second_node, options_);
    ADD_FAILURE() << "a second decoder started on " << data_;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("another vellum-decoder (pid " + std::to_string(getpid())),
              std::string::npos)
        << e.what();
  }
}

// A CALIBRATION arriving in the middle of a scan never applies to it; the scan's
// raw/calibration.yaml is the one it started with.
TEST_F(DecoderNodeTest, ACalibrationMidScanIsRefusedAndTheScanKeepsItsOwn) {
  Node node("vellum-decoder", &bus_.lcm(), &bus_.clock());
  DecoderNode decoder(&node, options_);
  bus_.Watch("vellum-decoder");
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  const Scan& scan = SmallScan();
  Start(71, 3);
  calibration_t own{};
  own.scan_id = 71;
  own.session = 3;
  own.source = "own";
  ToMessage(QuickRig(), &own);
  bus_.probe().Publish(channel::kCalibration, &own);
  for (int k = -1; k < static_cast<int>(scan.frames.size()); ++k) {
    capture_t c = Capture(71, 3, k);
    bus_.probe().Publish(channel::kCapture, &c);
    if (k == 2) {
      calibration_t later = own;
      later.source = "later";
      Calibration moved = QuickRig();
      moved.camera.matrix(0, 0) *= 1.1;
      ToMessage(moved, &later);
      bus_.probe().Publish(channel::kCalibration, &later);
    }
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(node.Counter("calibrations refused"), 1);
  Calibration recorded;
  ASSERT_TRUE(ReadCalibration(ScanFolder::For(data_, 71).calibration(), &recorded).ok());
  EXPECT_EQ(recorded.camera.matrix(0, 0), QuickRig().camera.matrix(0, 0));
}

TEST(DecoderNodeOptions, NonsenseIsRefusedByName) {
  DecoderNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.scan_timeout_s = 0;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("scan_timeout_s"), std::string::npos) << why;
  o = DecoderNodeOptions();
  o.data_dir.clear();
  EXPECT_FALSE(o.Check(&why));
  EXPECT_THROW(RequireValid(o), UsageError);
}

}  // namespace
}  // namespace vellum::station
