// The shell every station process shares: an LCM handle, typed subscriptions that report
// corrupt or wrong-type messages and sequence gaps instead of dropping them silently, a status
// heartbeat (1 Hz, and at once on a change or an error), a worker thread so that long work
// never blocks the LCM thread, clean shutdown on SIGTERM/SIGINT, and systemd's notify protocol
// (READY, WATCHDOG, STOPPING) when run as a Type=notify service.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "station/chunks.h"
#include "station/clock.h"
#include "station/message_versions.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/resend_request_t.hpp"
#include "vellum/scan_started_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {

// Microseconds since the epoch (the utime of every message).
int64_t NowUtime();

// The channel names of the process graph (docs/station.md).
namespace channel {
inline constexpr char kScanRequest[] = "SCAN_REQUEST";
inline constexpr char kScanStarted[] = "SCAN_STARTED";  // From the projector: a scan is on.
inline constexpr char kPatternShown[] = "PATTERN_SHOWN";
inline constexpr char kCapture[] = "CAPTURE";
inline constexpr char kCalibration[] = "CALIBRATION";
// A scan's extra lights (light_t): the projector asks, vellum-lights switches (or prompts the
// operator, who answers in the viewer), and the projector goes on when the light is on.
inline constexpr char kLightRequest[] = "LIGHT_REQUEST";
inline constexpr char kLightPrompt[] = "LIGHT_PROMPT";
inline constexpr char kLightOn[] = "LIGHT_ON";
inline constexpr char kTexture[] = "TEXTURE";  // From the decoder, as it sends a scan down.
inline constexpr char kLightTexture[] = "LIGHT_TEXTURE";  // Its extra lights' images, after it.
inline constexpr char kCorrespondence[] = "CORRESPONDENCE";
inline constexpr char kPointCloud[] = "POINT_CLOUD";
inline constexpr char kFlatMesh[] = "FLAT_MESH";
inline constexpr char kRestored[] = "RESTORED";
inline constexpr char kScanProgress[] = "SCAN_PROGRESS";  // A product handed on.
// A receiver asks a product's chunks again (resend_request_t): the bus lost them.
inline constexpr char kResend[] = "RESEND";
inline constexpr char kPreview[] = "PREVIEW";  // Camera preview, at most 640 px wide.
// The live preview's centre at the camera's full resolution (320 x 240 at most), for focusing.
inline constexpr char kPreviewFocus[] = "PREVIEW_FOCUS";
// The display's lag measured (`vellum calibrate latency`, the projector at start-up): the
// projector flashes, the camera says when it saw each flash.
inline constexpr char kLatencyRequest[] = "LATENCY_REQUEST";
inline constexpr char kLatencyProbe[] = "LATENCY_PROBE";
inline constexpr char kLatencySeen[] = "LATENCY_SEEN";
inline constexpr char kStatusPrefix[] = "STATUS_";  // + the process name, upper case
}  // namespace channel

// Status counters that another process acts on.
namespace counter {
// A product the bus lost that could not be had again (Assembler): the supervisor makes the
// scan again from disk.
inline constexpr char kProductsLost[] = "products lost";
// Chunks of a product, and whole products announced and never come, that the bus lost and a
// receiver asked again (Assembler): station_bench reports them beside its times.
inline constexpr char kChunksAskedAgain[] = "chunks asked again";
inline constexpr char kProductsAskedAgain[] = "products asked again";
// Scans this process failed (counted before the error that names the scan goes out): the
// projector stops a scan the decoder failed.
inline constexpr char kScansFailed[] = "scans failed";
// 1 when the restorer makes the albedo (it has a flat field) and so needs the projector's light
// (the decoder's amplitude) carried in CORRESPONDENCE and POINT_CLOUD, 0 when it does not: the
// decoder then leaves the light out, a quarter of those products' bytes. Not a count, a flag;
// a restorer that does not say is sent the light.
inline constexpr char kLightWanted[] = "projector light wanted";
}  // namespace counter

// A counter of a status message (`absent` when it has none).
int64_t StatusCounter(const status_t& msg, const std::string& name, int64_t absent = 0);

// The station id when none is configured. Stations that share a network (and a multicast
// group) need ids of their own (docs/station.md, "Several gantries in one room").
inline constexpr char kDefaultStation[] = "vellum";

// A station id: 1 to 64 of letters, digits, '-', '_' and '.'. Empty when valid, else why not.
std::string CheckStationId(const std::string& id);

// A scan's session: a random positive number the projector draws for each scan, carried by
// every message of the scan, so that a capture of another scan with the same id (a stale one,
// another gantry's) is never taken for one of this scan.
int64_t NewSession();

// Whether a message type carries the station it belongs to.
template <class Msg, class = void>
struct HasStation : std::false_type {};
template <class Msg>
struct HasStation<Msg, std::void_t<decltype(std::declval<Msg&>().station)>> : std::true_type {};
template <class Msg>
inline constexpr bool kHasStation = HasStation<Msg>::value;

// The status channel of a process: "vellum-camera" -> "STATUS_CAMERA".
std::string StatusChannel(const std::string& process);

// The default bus: multicast on this host only (ttl=0), with a 16 MB receive buffer (the kernel
// caps it at net.core.rmem_max: systemd/60-vellum.conf raises that).
inline constexpr char kDefaultUrl[] = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=16777216";

class Node {
 public:
  // Most jobs waiting for the worker: beyond, Post refuses work with an error (a flood of
  // messages must not grow a daemon without bound).
  static constexpr size_t kMaxQueuedJobs = 256;

  // Opens its own LCM handle on `url`. Throws std::runtime_error naming the URL when LCM
  // cannot start.
  Node(std::string process, const std::string& url);
  // Shares `lcm` (not owned; it outlives the node): several nodes in one process on one bus,
  // as the in-process tests drive them on memq://.
  // `clock` (not owned; it outlives the node) is the time its timeouts go by: a test's
  // SteppedClock, or the steady clock when null.
  Node(std::string process, lcm::LCM* lcm, const Clock* clock = nullptr);
  ~Node();
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  const std::string& process() const { return process_; }
  // The station this process belongs to (kDefaultStation unless set before subscribing):
  // messages of types that carry a station are stamped with it as they are published, and
  // those of another station are dropped as they arrive and counted ("from other stations").
  const std::string& station() const { return station_; }
  void SetStation(const std::string& station) { station_ = station; }
  lcm::LCM& lcm() { return *lcm_; }
  // The present by the node's clock (station/clock.h): what every timeout of a daemon's node
  // measures from.
  Clock::time_point Now() const { return clock_->Now(); }

  // Calls handler with each decoded message of `channel`, on the LCM thread. Messages that do
  // not decode as Msg are reported as errors (with their size) and dropped; a jump in a
  // publisher's seq is reported as lost messages (an error, unless RecoversLosses(channel)).
  template <class Msg>
  void Subscribe(const std::string& channel, std::function<void(const Msg&)> handler) {
    SubscribeRaw(channel, [this, channel, handler](const lcm::ReceiveBuffer* buffer) {
      Msg msg;
      if (!SafeDecode(buffer->data, buffer->data_size, &msg)) {
        Error(channel + ": a message of " + std::to_string(buffer->data_size) +
              " bytes does not decode as vellum." + Msg::getTypeName() +
              " (corrupt, truncated or of another type); dropped");
        return;
      }
      if constexpr (kHasStation<Msg>) {
        if (msg.station != station_) {
          OtherStation(channel, msg.station);
          return;
        }
      }
      CheckSequence(channel, msg.seq);
      handler(msg);
    });
  }

  // Sets msg->seq (this process's counter for the channel), msg->station where the type has
  // one, and msg->utime when it is 0; then publishes.
  template <class Msg>
  void Publish(const std::string& channel, Msg* msg) {
    Stamp(channel, msg);
    if (lcm_->publish(channel, msg) != 0) Error(channel + ": publish failed");
  }

  // Publishes the chunks of one product (of scan `scan_id`) paced at about SetPace's rate: a
  // burst of many megabytes overflows the receivers' socket buffers, and udpm loses a whole
  // message with any of its fragments. The product is held, as sent, for a while (kHoldScans,
  // kHoldSeconds, kHoldBytes): a receiver that missed chunks asks for them on RESEND, and they
  // go again byte for byte ("chunks sent again"). The chunks are encoded into the buffers of
  // products no longer held, when there are some ("chunk buffers reused").
  template <class Msg>
  void PublishChunks(const std::string& channel, std::vector<Msg>* chunks) {
    static_cast<void>(PublishChunks(channel, chunks, nullptr));
  }
  // The same, with `before_last` run before the last chunk goes: a sender's files written while
  // its other chunks travel are on disk before a receiver can have the whole product. When it
  // fails, the last chunk is not sent, nothing is held, and its status is returned (a receiver
  // never has that product whole). Each chunk is stamped where it lies in `chunks`.
  template <class Msg>
  Status PublishChunks(const std::string& channel, std::vector<Msg>* chunks,
                       const std::function<Status()>& before_last) {
    return PublishEach<Msg>(
        channel, static_cast<int>(chunks->size()),
        [chunks](int k) -> Msg& { return (*chunks)[static_cast<size_t>(k)]; }, before_last);
  }
  // The same for chunks made one at a time, each encoded as it is made.
  template <class Msg>
  Status PublishChunks(const std::string& channel, const ChunkMaker<Msg>& chunks,
                       const std::function<Status()>& before_last = nullptr) {
    Msg m{};
    return PublishEach<Msg>(
        channel, chunks.count,
        [&chunks, &m](int k) -> Msg& {
          chunks.make(k, &m);
          return m;
        },
        before_last);
  }
  void SetPace(double bytes_per_second) { pace_ = bytes_per_second; }
  // What is held for RESEND: the products of each channel's newest kHoldScans scans, sent in
  // the last kHoldSeconds, at most kHoldBytes beyond the newest product.
  static constexpr int kHoldScans = 2;
  static constexpr double kHoldSeconds = 60;
  static constexpr size_t kHoldBytes = size_t{256} << 20;

  // Status: the state ("idle", "busy", "scanning", ...), the scan and a line for the operator.
  void SetState(const std::string& state, int64_t scan_id = 0, const std::string& detail = "");
  // Reports an error on stderr and on the status channel (at once); the process goes on.
  void Error(const std::string& message, int64_t scan_id = 0);
  // A scan failed in this process: reports "scan <id>: <message>" as an error about the scan,
  // and the process is idle again.
  void FailScan(int64_t scan_id, const std::string& message);
  // A line on stderr for the log (journald under systemd).
  void Log(const std::string& message) const;
  void Count(const std::string& counter, int64_t n = 1);
  int64_t Counter(const std::string& counter) const;
  // What `channel` loses is asked again (its Assembler): a lost message there is logged and
  // counted, not an error; the error comes if the product is given up.
  void RecoversLosses(const std::string& channel);

  // Runs `work` on the worker thread, in the order posted. With kMaxQueuedJobs waiting, the
  // work is refused: reported as an error (naming `what`) and counted; returns false.
  bool Post(std::function<void()> work, const std::string& what = "a job");
  // Work posted and not yet finished.
  size_t Pending() const;
  // Waits until every job posted so far has run. A daemon's node class calls it as it is
  // destroyed, so that no job of it runs after its members are gone.
  void Drain() const;

  // The longest one job may run on the worker before the process is reported stuck (a hung
  // stage): from then on its status says so and systemd's watchdog is no longer fed, so that
  // systemd restarts it. And the longest Run waits, once stopped, for the worker to finish.
  void SetWorkLimits(double stuck_after_s, double stop_grace_s) {
    stuck_after_s_ = stuck_after_s;
    stop_grace_s_ = stop_grace_s;
  }
  // What the worker is doing and for how long (seconds); "" and 0 when idle.
  std::string Working(double* seconds) const;

  // Handles LCM messages and calls `tick` about every tick_ms until SIGTERM/SIGINT or Stop();
  // then finishes the posted work and returns 0. When the worker has not finished within the
  // stop grace (a hung job), leaves it: ends the process with status 1 at once when
  // ExitWhenHung() was called (a daemon: no orderly teardown can wait for the job), else returns
  // 1 (Abandoned(); Drain no longer waits).
  int Run(const std::function<void()>& tick = nullptr, int tick_ms = 50);
  void ExitWhenHung() { exit_when_hung_ = true; }
  bool Abandoned() const { return abandoned_; }
  void Stop() { stop_ = true; }
  bool Stopping() const;

 private:
  // A chunked product as it was sent, for RESEND.
  struct HeldProduct {
    std::string channel;
    int64_t scan_id = 0;
    std::vector<int64_t> seqs;                 // Each chunk's seq, in chunk order.
    std::vector<std::vector<uint8_t>> chunks;  // Each chunk's encoded message.
    std::chrono::steady_clock::time_point sent = std::chrono::steady_clock::now();
  };
  // PublishChunks' one loop: chunk k of `count` is `at(k)`, stamped, encoded and sent.
  template <class Msg>
  Status PublishEach(const std::string& channel, int count, const std::function<Msg&(int)>& at,
                     const std::function<Status()>& before_last) {
    HeldProduct held;
    held.channel = channel;
    for (int k = 0; k < count; ++k) {
      const bool last = k + 1 == count;
      if (before_last && last) {
        const Status ready = before_last();
        if (!ready.ok()) return ready;
      }
      const auto start = std::chrono::steady_clock::now();
      Msg& m = at(k);
      Stamp(channel, &m);
      std::vector<uint8_t> bytes = SpareBuffer();
      bytes.resize(static_cast<size_t>(m.getEncodedSize()));  // Every byte encoded over.
      m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
      held.scan_id = m.scan_id;
      held.seqs.push_back(m.seq);
      if (last) {
        // Held before the last chunk goes: a receiver that finds chunks missing when it comes
        // asks at once (Assembler), and is answered.
        held.chunks.push_back(bytes);
        Hold(std::move(held));
        PublishBytes(channel, bytes);
        break;
      }
      PublishBytes(channel, bytes);
      held.chunks.push_back(std::move(bytes));
      std::this_thread::sleep_until(
          start + std::chrono::duration<double>(held.chunks.back().size() / pace_));
    }
    return Status::Ok();
  }
  template <class Msg>
  void Stamp(const std::string& channel, Msg* msg) {
    if constexpr (kHasStation<Msg>) msg->station = station_;
    msg->seq = NextSeq(channel);
    if (msg->utime == 0) msg->utime = NowUtime();
  }
  void PublishBytes(const std::string& channel, const std::vector<uint8_t>& bytes);
  void Hold(HeldProduct product);
  // A buffer for one encoded chunk: a spare one when there is one, else empty.
  std::vector<uint8_t> SpareBuffer();
  // LCM thread: sends again the chunks a RESEND asks for, if this process holds the product.
  void OnResend(const resend_request_t& msg);
  struct RawHandler {
    std::function<void(const lcm::ReceiveBuffer*)> f;
    void Handle(const lcm::ReceiveBuffer* buffer, const std::string&) { f(buffer); }
  };
  void SubscribeRaw(const std::string& channel,
                    std::function<void(const lcm::ReceiveBuffer*)> handler);
  void CheckSequence(const std::string& channel, int64_t seq);
  // Counts a message of another station (and logs the first from each, a few at most).
  void OtherStation(const std::string& channel, const std::string& station);
  int64_t NextSeq(const std::string& channel);
  void PublishStatus();
  void WorkerLoop();

  std::string process_;
  const Clock* clock_ = &Clock::Steady();
  std::string station_ = kDefaultStation;
  std::unique_ptr<lcm::LCM> own_lcm_;  // Null when the bus is shared.
  lcm::LCM* lcm_;
  std::vector<std::unique_ptr<RawHandler>> handlers_;
  // Taken back when the node goes, so that a bus outliving it (a test's) never calls into it.
  std::vector<lcm::Subscription*> subscriptions_;
  std::atomic<bool> stop_{false};
  double pace_ = 800e6;  // Bytes per second of chunked products (--pace).

  // Guards the sequence numbers, the status (state, detail, errors) and the counters below:
  // the LCM thread and the worker both report.
  mutable std::mutex mutex_;
  // What this process publishes: each channel's counter, from seq_start_ (random per process,
  // 2^40 apart on average: two publishers on a channel, or one restarted, never share a range).
  std::map<std::string, int64_t> seq_out_;
  int64_t seq_start_ = 0;
  // What it hears: per channel, the publishers (each the last seq of its run), the most recently
  // heard first, a few at most (SeqStreams).
  std::map<std::string, std::vector<int64_t>> seq_in_;
  std::set<std::string> recovered_;         // RecoversLosses's channels.
  std::vector<std::string> others_logged_;  // Other stations heard (the first few).
  std::string state_ = "starting", detail_, last_error_;
  int64_t scan_id_ = 0, errors_ = 0, last_error_utime_ = 0, last_error_scan_ = 0;
  std::map<std::string, int64_t> counters_;

  mutable std::mutex work_mutex_;  // Guards work_, working_on_, work_start_ and work_done_ (posted
                                   // by any thread, run by the worker).
  std::condition_variable work_cv_;
  std::deque<std::pair<std::function<void()>, std::string>> work_;  // The job and what it is.
  std::string working_on_;                            // The job running ("" when idle).
  std::chrono::steady_clock::time_point work_start_;  // When it began.
  double stuck_after_s_ = 600, stop_grace_s_ = 20;
  std::atomic<bool> abandoned_{false};
  bool exit_when_hung_ = false;
  std::atomic<size_t> pending_{0};
  std::mutex held_mutex_;         // Guards held_ and spare_.
  std::deque<HeldProduct> held_;  // Oldest first (the worker holds, the LCM thread sends again).
  // The encoded chunks of products no longer held (at most kSpareBytes), for the next
  // product's chunks: their pages are in memory already (faulting in fresh ones was most of the
  // 25 ms a 16 MB product took to encode, docs/measurements.md).
  std::vector<std::vector<uint8_t>> spare_;
  size_t spare_bytes_ = 0;
  static constexpr size_t kSpareBytes = size_t{64} << 20;
  bool work_done_ = false;
  std::thread worker_;
};

// systemd's notify protocol without libsystemd: a datagram to $NOTIFY_SOCKET, if set.
void NotifySystemd(const std::string& state);

}  // namespace vellum::station
