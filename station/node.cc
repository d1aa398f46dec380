#include "station/node.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <stdexcept>

#include "core/common/text.h"
#include "core/geometry/calibration.h"
#include "vellum/status_t.hpp"

namespace vellum::station {
namespace {

std::atomic<bool> g_signalled{false};

void OnSignal(int) { g_signalled = true; }

}  // namespace

int64_t NowUtime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string StatusChannel(const std::string& process) {
  std::string name = process.rfind("vellum-", 0) == 0 ? process.substr(7) : process;
  for (char& c : name) c = c == '-' ? '_' : static_cast<char>(std::toupper(c));
  return channel::kStatusPrefix + name;
}

void NotifySystemd(const std::string& state) {
  const char* path = std::getenv("NOTIFY_SOCKET");
  if (!path || !*path) return;
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (std::strlen(path) >= sizeof(addr.sun_path)) return;
  std::strcpy(addr.sun_path, path);
  socklen_t len = sizeof(sa_family_t) + std::strlen(path);
  if (addr.sun_path[0] == '@') addr.sun_path[0] = '\0';  // Abstract socket.
  const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return;
  (void)sendto(fd, state.data(), state.size(), MSG_NOSIGNAL, reinterpret_cast<sockaddr*>(&addr),
               len);
  close(fd);
}

namespace {

// Where a process's message counters start: random below 2^48, so that the publishers of a
// channel (and one restarted) count in ranges of their own.
int64_t RandomSeqStart() {
  std::random_device device;
  const uint64_t bits = (static_cast<uint64_t>(device()) << 32) | device();
  return static_cast<int64_t>(bits >> 16);
}

}  // namespace

Node::Node(std::string process, const std::string& url)
    : process_(std::move(process)),
      own_lcm_(std::make_unique<lcm::LCM>(url)),
      lcm_(own_lcm_.get()),
      seq_start_(RandomSeqStart()) {
  if (!lcm_->good()) {
    throw std::runtime_error(
        "cannot open the LCM bus '" + url +
        "' (for udpm: is there a multicast route? see docs/operator.md, Troubleshooting)");
  }
  std::signal(SIGTERM, OnSignal);
  std::signal(SIGINT, OnSignal);
  Subscribe<resend_request_t>(channel::kResend,
                              [this](const resend_request_t& msg) { OnResend(msg); });
  worker_ = std::thread([this] { WorkerLoop(); });
}

Node::Node(std::string process, lcm::LCM* lcm, const Clock* clock)
    : process_(std::move(process)),
      clock_(clock ? clock : &Clock::Steady()),
      lcm_(lcm),
      seq_start_(RandomSeqStart()) {
  Subscribe<resend_request_t>(channel::kResend,
                              [this](const resend_request_t& msg) { OnResend(msg); });
  worker_ = std::thread([this] { WorkerLoop(); });
}

Node::~Node() {
  for (lcm::Subscription* s : subscriptions_) lcm_->unsubscribe(s);
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    work_done_ = true;
  }
  work_cv_.notify_all();
  if (!worker_.joinable()) return;
  if (abandoned_ && Pending() > 0) {
    worker_.detach();  // Hung: the process is exiting (DaemonMain ends it at once).
  } else {
    worker_.join();
  }
}

bool Node::Stopping() const { return stop_ || g_signalled; }

void Node::Log(const std::string& message) const {
  std::fprintf(stderr, "%s: %s\n", process_.c_str(), message.c_str());
}

void Node::SubscribeRaw(const std::string& channel,
                        std::function<void(const lcm::ReceiveBuffer*)> handler) {
  handlers_.push_back(std::make_unique<RawHandler>(RawHandler{std::move(handler)}));
  subscriptions_.push_back(lcm_->subscribe(channel, &RawHandler::Handle, handlers_.back().get()));
}

int64_t StatusCounter(const status_t& msg, const std::string& name, int64_t absent) {
  const size_t n = std::min(msg.counter_names.size(), msg.counter_values.size());
  for (size_t k = 0; k < n; ++k) {
    if (msg.counter_names[k] == name) return msg.counter_values[k];
  }
  return absent;
}

void Node::PublishBytes(const std::string& channel, const std::vector<uint8_t>& bytes) {
  if (lcm_->publish(channel, bytes.data(), static_cast<unsigned int>(bytes.size())) != 0) {
    Error(channel + ": publish failed");
  }
}

void Node::Hold(HeldProduct product) {
  std::lock_guard<std::mutex> lock(held_mutex_);
  held_.push_back(std::move(product));
  // The newest always stays; older ones while they are of their channel's kHoldScans newest
  // scans, recent, and fit in kHoldBytes.
  const auto now = std::chrono::steady_clock::now();
  std::map<std::string, std::vector<int64_t>> scans;  // Per channel, newest first.
  std::vector<uint8_t> keep(held_.size(), 0);
  size_t bytes = 0;
  for (size_t i = held_.size(); i-- > 0;) {
    const HeldProduct& h = held_[i];
    std::vector<int64_t>& ids = scans[h.channel];
    if (std::find(ids.begin(), ids.end(), h.scan_id) == ids.end()) ids.push_back(h.scan_id);
    size_t size = 0;
    for (const auto& chunk : h.chunks) size += chunk.size();
    keep[i] = i + 1 == held_.size() ||
              (ids.size() <= static_cast<size_t>(kHoldScans) && bytes + size <= kHoldBytes &&
               now - h.sent <= std::chrono::duration<double>(kHoldSeconds));
    if (keep[i]) bytes += size;
  }
  std::deque<HeldProduct> kept;
  for (size_t i = 0; i < held_.size(); ++i) {
    if (keep[i]) {
      kept.push_back(std::move(held_[i]));
      continue;
    }
    for (std::vector<uint8_t>& chunk : held_[i].chunks) {
      if (spare_bytes_ + chunk.capacity() > kSpareBytes) break;
      spare_bytes_ += chunk.capacity();
      spare_.push_back(std::move(chunk));
    }
  }
  held_.swap(kept);
}

std::vector<uint8_t> Node::SpareBuffer() {
  std::vector<uint8_t> buffer;
  {
    std::lock_guard<std::mutex> lock(held_mutex_);
    if (spare_.empty()) return buffer;
    buffer = std::move(spare_.back());
    spare_.pop_back();
    spare_bytes_ -= buffer.capacity();
  }
  Count("chunk buffers reused");
  return buffer;
}

void Node::OnResend(const resend_request_t& msg) {
  std::vector<std::vector<uint8_t>> again;
  {
    std::lock_guard<std::mutex> lock(held_mutex_);
    for (const HeldProduct& held : held_) {
      if (held.channel != msg.channel || held.scan_id != msg.scan_id) continue;
      if (msg.known_seq == 0) {  // Every product of the scan on the channel, whole.
        again.insert(again.end(), held.chunks.begin(), held.chunks.end());
        continue;
      }
      if (std::find(held.seqs.begin(), held.seqs.end(), msg.known_seq) == held.seqs.end()) continue;
      for (int32_t index : msg.chunks) {
        if (index >= 0 && static_cast<size_t>(index) < held.chunks.size()) {
          again.push_back(held.chunks[static_cast<size_t>(index)]);
        }
      }
      break;
    }
  }
  if (again.empty()) return;  // Not ours, or no longer held: the asker gives up in time.
  Log(Printable(msg.process, 64) + " missed " + std::to_string(again.size()) + " chunk(s) of " +
      Printable(msg.channel, 64) + " of scan " + std::to_string(msg.scan_id) +
      "; sending them again");
  // Paced as the first send, on the LCM thread (a whole point cloud of 1600 x 1200 takes a
  // quarter of a second).
  for (const auto& bytes : again) {
    const auto start = std::chrono::steady_clock::now();
    PublishBytes(msg.channel, bytes);
    std::this_thread::sleep_until(start + std::chrono::duration<double>(bytes.size() / pace_));
  }
  Count("chunks sent again", static_cast<int64_t>(again.size()));
}

void Node::CheckSequence(const std::string& channel, int64_t seq) {
  // Each publisher counts its own messages on a channel, from a random start: a message carries
  // no publisher's name, so it is matched to the publisher whose last seq lies just below its
  // own (within kGap); one matching none is a new publisher (another daemon on the channel, a
  // restarted one, a replayed log), followed from there, nothing lost.
  constexpr int64_t kGap = 1 << 20;  // More messages than a scan sends on any channel.
  constexpr size_t kPublishers = 8;
  int64_t lost = 0, last = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<int64_t>& heard = seq_in_[channel];
    counters_["received " + channel] += 1;
    if (std::any_of(heard.begin(), heard.end(),
                    [&](int64_t before) { return seq <= before && before - seq <= kGap; })) {
      // A message heard before from the same publisher, sent again (RESEND): nothing lost, and
      // its publisher's count goes on from where it was.
      counters_["heard again " + channel] += 1;
      return;
    }
    auto it = std::find_if(heard.begin(), heard.end(),
                           [&](int64_t before) { return seq > before && seq - before <= kGap; });
    if (it != heard.end()) {
      if (seq > *it + 1) {
        lost = seq - *it - 1;
        last = *it;
      }
      heard.erase(it);
    } else if (heard.size() >= kPublishers) {
      heard.pop_back();  // The one heard longest ago.
    }
    heard.insert(heard.begin(), seq);
  }
  if (lost == 0) return;
  Count("lost messages", lost);
  const std::string what = channel + ": " + std::to_string(lost) +
                           " message(s) lost on the bus (seq " + std::to_string(last) + " then " +
                           std::to_string(seq) + ")";
  bool recovered = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    recovered = recovered_.count(channel) > 0;
  }
  if (recovered) {
    Log(what + "; asking again");
  } else {
    Error(what);
  }
}

void Node::RecoversLosses(const std::string& channel) {
  std::lock_guard<std::mutex> lock(mutex_);
  recovered_.insert(channel);
}

void Node::OtherStation(const std::string& channel, const std::string& station) {
  bool first = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    counters_["from other stations"] += 1;
    if (others_logged_.size() < 8 &&
        std::find(others_logged_.begin(), others_logged_.end(), station) == others_logged_.end()) {
      others_logged_.push_back(station);
      first = true;
    }
  }
  if (first) {
    Log(channel + ": messages of station \"" + Printable(station, 64) +
        "\" are ignored (this is station \"" + station_ + "\"); counted as 'from other stations'");
  }
}

int64_t NewSession() {
  static std::mutex mutex;
  static std::mt19937_64 random(std::random_device{}());
  std::lock_guard<std::mutex> lock(mutex);
  return static_cast<int64_t>(random() >> 2) + 1;
}

std::string CheckStationId(const std::string& id) {
  if (id.empty() || id.size() > 64) return "a station id has 1 to 64 characters";
  for (const char c : id) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') {
      return "a station id has only letters, digits, '-', '_' and '.'";
    }
  }
  return "";
}

int64_t Node::NextSeq(const std::string& channel) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto [it, first] = seq_out_.emplace(channel, seq_start_);
  return it->second++;
}

void Node::SetState(const std::string& state, int64_t scan_id, const std::string& detail) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state == state_ && scan_id == scan_id_ && detail == detail_) return;
    state_ = state;
    scan_id_ = scan_id;
    detail_ = detail;
  }
  PublishStatus();
}

void Node::Error(const std::string& message, int64_t scan_id) {
  Log("error: " + message);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++errors_;
    last_error_ = message;
    last_error_utime_ = NowUtime();
    last_error_scan_ = scan_id;
  }
  PublishStatus();
}

void Node::FailScan(int64_t scan_id, const std::string& message) {
  Error("scan " + std::to_string(scan_id) + ": " + message, scan_id);
  SetState("idle");
}

void Node::Count(const std::string& counter, int64_t n) {
  std::lock_guard<std::mutex> lock(mutex_);
  counters_[counter] += n;
}

int64_t Node::Counter(const std::string& counter) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = counters_.find(counter);
  return it == counters_.end() ? 0 : it->second;
}

void Node::PublishStatus() {
  status_t msg;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    msg.utime = 0;
    msg.process = process_;
    msg.pid = static_cast<int32_t>(getpid());
    msg.state = state_;
    msg.scan_id = scan_id_;
    msg.detail = detail_;
    for (const auto& [name, value] : counters_) {
      msg.counter_names.push_back(name);
      msg.counter_values.push_back(value);
    }
    msg.ncounters = static_cast<int32_t>(msg.counter_names.size());
    msg.errors = errors_;
    msg.last_error = last_error_;
    msg.last_error_utime = last_error_utime_;
    msg.last_error_scan_id = last_error_scan_;
  }
  Publish(StatusChannel(process_), &msg);
}

bool Node::Post(std::function<void()> work, const std::string& what) {
  bool full = false;
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    full = work_.size() >= kMaxQueuedJobs;
    if (!full) {
      ++pending_;
      work_.emplace_back(std::move(work), what);
    }
  }
  if (full) {
    Count("jobs refused");
    Error("worker busy with " + std::to_string(kMaxQueuedJobs) + " jobs waiting: " + what +
          " dropped");
    return false;
  }
  work_cv_.notify_one();
  return true;
}

size_t Node::Pending() const { return pending_; }

void Node::Drain() const {
  while (pending_ > 0 && !abandoned_) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

void Node::WorkerLoop() {
  for (;;) {
    std::function<void()> work;
    {
      std::unique_lock<std::mutex> lock(work_mutex_);
      work_cv_.wait(lock, [&] { return work_done_ || !work_.empty(); });
      if (work_.empty()) return;
      work = std::move(work_.front().first);
      working_on_ = std::move(work_.front().second);
      work_start_ = std::chrono::steady_clock::now();
      work_.pop_front();
    }
    try {
      work();
    } catch (const std::exception& e) {
      Error(std::string("internal error: ") + e.what());
    }
    {
      std::lock_guard<std::mutex> lock(work_mutex_);
      working_on_.clear();
    }
    --pending_;
  }
}

std::string Node::Working(double* seconds) const {
  std::lock_guard<std::mutex> lock(work_mutex_);
  *seconds =
      working_on_.empty()
          ? 0
          : std::chrono::duration<double>(std::chrono::steady_clock::now() - work_start_).count();
  return working_on_;
}

int Node::Run(const std::function<void()>& tick, int tick_ms) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state_ == "starting") state_ = "idle";
  }
  PublishStatus();
  NotifySystemd("READY=1\nSTATUS=" + process_ + " on the bus");
  Log("running (pid " + std::to_string(getpid()) + ")");
  auto next_beat = std::chrono::steady_clock::now();
  bool stuck = false;
  while (!Stopping()) {
    lcm_->handleTimeout(tick_ms);
    if (tick) tick();
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_beat) {
      // A job past its limit is a hung stage: said once, and the watchdog starves, so that
      // systemd restarts the process (the supervisor then takes the scan up from disk).
      double seconds = 0;
      const std::string job = Working(&seconds);
      if (!job.empty() && seconds > stuck_after_s_) {
        if (!stuck) {
          Count("stuck");
          Error("stuck: " + job + " has run for " + std::to_string(static_cast<int>(seconds)) +
                " s (limit " + std::to_string(static_cast<int>(stuck_after_s_)) +
                " s); systemd's watchdog is no longer fed");
          int64_t scan = 0;
          {
            std::lock_guard<std::mutex> lock(mutex_);
            scan = scan_id_;
          }
          SetState("stuck", scan, job);
        }
        stuck = true;
      } else {
        stuck = false;
      }
      PublishStatus();
      if (!stuck) NotifySystemd("WATCHDOG=1");
      next_beat = now + std::chrono::seconds(1);
    }
  }
  NotifySystemd("STOPPING=1");
  Log("stopping: finishing " + std::to_string(Pending()) + " posted job(s)");
  SetState("stopping");
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(stop_grace_s_);
  while (Pending() > 0) {
    if (std::chrono::steady_clock::now() > give_up) {
      double seconds = 0;
      const std::string job = Working(&seconds);
      Log("stopping: the worker is still in " + (job.empty() ? std::string("a job") : job) +
          " after " + std::to_string(static_cast<int>(stop_grace_s_)) +
          " s; leaving it (a scan it held is taken up again from disk on restart)");
      abandoned_ = true;
      if (exit_when_hung_) {
        std::fflush(nullptr);
        std::_Exit(1);
      }
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  Log("stopped");
  return 0;
}

}  // namespace vellum::station
