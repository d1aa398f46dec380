// The decoder's node on an in-process bus: a scan's captures are recorded as they arrive and
// the whole scan is sent down the chain (TEXTURE, CORRESPONDENCE with the decode report,
// SCAN_PROGRESS); bad captures are reported and the node goes on; an incomplete scan is given
// up after its timeout with the missing captures named, and the next scan is recorded whole.
#include "daemons/decoder/decoder_node.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <set>

#include "io/scan_io.h"
#include "station/messages.h"
#include "station/scan_log.h"
#include "station/testing.h"
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

  std::string data_;
  DecoderNodeOptions options_;
  MemqBus bus_;
};

TEST_F(DecoderNodeTest, RecordsAScanAndSendsItDownTheChain) {
  Node node("vellum-decoder", &bus_.lcm());
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
  EXPECT_EQ(node.Counter("scans decoded"), 1);
}

TEST_F(DecoderNodeTest, BadCapturesAreReportedAndTheNodeGoesOn) {
  Node node("vellum-decoder", &bus_.lcm());
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
  EXPECT_TRUE(bus_.WaitForError("vellum-decoder", "scan 0, pattern 1: CAPTURE refused"))
      << bus_.Status("vellum-decoder").last_error;
  // The node goes on: a whole scan after the bad ones is recorded and decoded.
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishScan(22);
  EXPECT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(node.Counter("scans decoded"), 1);
}

TEST_F(DecoderNodeTest, AnIncompleteScanIsGivenUpNamingWhatIsMissingAndTheNextIsWhole) {
  Node node("vellum-decoder", &bus_.lcm());
  DecoderNode decoder(&node, options_);
  bus_.AddTick([&] { decoder.Tick(); });
  bus_.Watch("vellum-decoder");
  PublishScan(31, /*skip=*/4);
  const int total = static_cast<int>(SmallScan().frames.size()) + 1;
  ASSERT_TRUE(bus_.WaitForError("vellum-decoder", "scan 31 failed: no capture for 1 s", 30))
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

// The supervisor in the decoder: a restarted daemon (a new pid in its heartbeat) is sent again
// only the scans it held; a scan already past it is not processed twice.
TEST_F(DecoderNodeTest, ARestartedDaemonIsSentAgainOnlyTheScansItHeld) {
  Node node("vellum-decoder", &bus_.lcm());
  DecoderNode decoder(&node, options_);
  auto correspondence = bus_.Record<correspondence_t>(channel::kCorrespondence);
  auto heartbeat = [&](const std::string& process, int32_t pid) {
    status_t m{};
    m.process = process;
    m.pid = pid;
    m.state = "idle";
    bus_.probe().Publish(StatusChannel(process), &m);
  };
  auto handed_on = [&](const std::string& process, int64_t id) {
    scan_progress_t m{};
    m.scan_id = id;
    m.process = process;
    m.pid = 1;
    m.product = "x";
    bus_.probe().Publish(channel::kScanProgress, &m);
  };
  auto sent = [&](int64_t id) {
    int n = 0;
    for (const correspondence_t& m : *correspondence) n += m.scan_id == id && m.chunk_index == 0;
    return n;
  };
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

}  // namespace
}  // namespace vellum::station
