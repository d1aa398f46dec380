#include "station/supervisor.h"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>

#include "io/scan_io.h"
#include "station/chain.h"
#include "vellum/restored_t.hpp"
#include "vellum/scan_progress_t.hpp"

namespace vellum::station {
namespace fs = std::filesystem;

Status MarkPending(const ScanFolder& folder, int attempts) {
  const std::string tmp = folder.pending() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << attempts << "\n";
    out.flush();
    if (!out) return Status::Error("cannot write " + tmp);
  }
  std::error_code ec;
  fs::rename(tmp, folder.pending(), ec);  // Whole or not at all.
  if (ec) return Status::Error("cannot write " + folder.pending() + ": " + ec.message());
  return Status::Ok();
}

int PendingAttempts(const ScanFolder& folder) {
  std::ifstream in(folder.pending());
  int attempts = 0;
  if (!(in >> attempts)) return in.is_open() ? 1 : 0;  // Unreadable: counts as one attempt.
  return std::max(attempts, 1);
}

void ClearPending(const ScanFolder& folder) {
  std::error_code ec;
  fs::remove(folder.pending(), ec);
}

std::vector<int64_t> FindPending(const std::string& data_dir) {
  std::vector<int64_t> ids;
  std::error_code ec;
  for (fs::directory_iterator it(data_dir, ec), end; !ec && it != end; it.increment(ec)) {
    const int64_t id = ScanFolderId(it->path().filename().string());
    if (id > 0 && PathExists((it->path() / "pending").string())) {
      ids.push_back(id);
    }
  }
  std::sort(ids.begin(), ids.end());
  return ids;
}

void AnnounceHandedOn(Node* node, int64_t scan_id, const std::string& product,
                      const std::string& counter) {
  scan_progress_t m{};
  m.scan_id = scan_id;
  m.process = node->process();
  m.pid = static_cast<int32_t>(getpid());
  m.product = product;
  node->Publish(channel::kScanProgress, &m);
  if (!counter.empty()) node->Count(counter);
}

Supervisor::Supervisor(Node* node, std::string data_dir, Send send)
    : node_(node), data_(std::move(data_dir)), send_(std::move(send)) {
  for (size_t k = 1; k < kChainLength; ++k) {
    node->Subscribe<status_t>(StatusChannel(kChain[k].process), [this](const status_t& msg) {
      node_->Post([this, msg] { OnStatus(msg); }, "a status");
    });
  }
  node->Subscribe<scan_progress_t>(channel::kScanProgress, [this](const scan_progress_t& msg) {
    const int index = ChainIndex(msg.process);
    if (index < 0 || msg.scan_id <= 0) return;
    const int64_t id = msg.scan_id;
    node_->Post(
        [this, id, index] {
          auto it = reached_.find(id);
          if (it != reached_.end()) it->second = std::max(it->second, index);
        },
        "a scan's progress");
  });
  node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& msg) {
    const int64_t id = msg.scan_id;
    node_->Post([this, id] { Finished(id); }, "a RESTORED");
  });
}

bool Supervisor::Recorded(int64_t scan_id, const Scan& scan) {
  const Status s = MarkPending(ScanFolder::For(data_, scan_id), 1);
  if (!s.ok()) {
    node_->Error("scan " + std::to_string(scan_id) + ": " + s.message(), scan_id);
    return false;
  }
  reached_[scan_id] = -1;  // Recorded, not yet handed on.
  if (send_(scan_id, scan).ok()) reached_[scan_id] = std::max(reached_[scan_id], 0);
  return true;
}

void Supervisor::Failed(int64_t scan_id, const std::string& why) {
  Finished(scan_id);
  const Status s = MarkFailed(ScanFolder::For(data_, scan_id), why);
  if (!s.ok()) node_->Log("scan " + std::to_string(scan_id) + ": " + s.message());
}

void Supervisor::Finished(int64_t scan_id) {
  ClearPending(ScanFolder::For(data_, scan_id));
  reached_.erase(scan_id);
}

void Supervisor::OnStatus(const status_t& msg) {
  const int index = ChainIndex(msg.process);
  if (index <= 0) return;
  if (static_cast<size_t>(index) + 1 == kChainLength) {  // The restorer, the light's only user.
    light_wanted_ = StatusCounter(msg, counter::kLightWanted, /*absent=*/1) != 0;
  }
  if (daemons_.count(msg.process) == 0) node_->Count("processing daemons heard");
  Daemon& seen = daemons_[msg.process];
  if (seen.pid != 0 && msg.pid != seen.pid) {
    // Whatever it held is lost: the scans last handed on by the daemon before it.
    node_->Count("restarts seen");
    SendAgain(
        [&](int64_t id) {
          auto it = reached_.find(id);
          return it != reached_.end() && it->second == index - 1;
        },
        msg.process + " restarted");
  }
  seen.pid = msg.pid;
  // Once every processing daemon listens, scans in the ledger that no one holds (the station
  // stopped) go again. A scan this process sent is not: it is on its way, its daemons' statuses
  // having come in behind it (or lost on a loaded bus), and sent again it would be flattened and
  // restored twice at once, into the same folder. Its product is announced again instead: a
  // daemon that was not listening when it went asks for it again, from the daemon that holds it
  // (Assembler::AwaitAnnounced), and one that has it lets the announcement pass.
  if (!sent_at_start_ && daemons_.size() == kChainLength - 1) {
    sent_at_start_ = true;
    for (const auto& [id, index] : reached_) {
      if (index >= 0 && static_cast<size_t>(index) + 1 < kChainLength) {
        AnnounceHandedOn(node_, id, kChain[index].product, "products announced again");
      }
    }
    SendAgain(
        [this](int64_t id) {
          auto it = reached_.find(id);
          return it == reached_.end() || it->second < 0;
        },
        "the chain was not whole (the station stopped, or a daemon had not started)");
  }
  const int64_t products_lost = StatusCounter(msg, counter::kProductsLost);
  const bool lost_on_bus = seen.error_utime != -1 && products_lost > seen.products_lost;
  seen.products_lost = products_lost;
  if (msg.last_error_utime > seen.error_utime && msg.last_error_scan_id > 0 &&
      seen.error_utime != -1) {
    const int64_t id = msg.last_error_scan_id;
    // Failed downstream, with a status the operator sees; marked so on disk, if it is ours. A
    // product the bus lost is made again from the scan's captures on disk instead (parked
    // after kMaxAttempts like any other).
    if (lost_on_bus && reached_.count(id) > 0) {
      seen.error_utime = msg.last_error_utime;
      SendAgain([id](int64_t pending) { return pending == id; },
                msg.process + " lost its input on the bus (" + msg.last_error + ")");
      return;
    }
    if (PathExists(ScanFolder::For(data_, msg.last_error_scan_id).raw())) {
      Failed(msg.last_error_scan_id, msg.process + ": " + msg.last_error);
    } else {
      Finished(msg.last_error_scan_id);
    }
  }
  seen.error_utime = msg.last_error_utime;
}

void Supervisor::SendAgain(const std::function<bool(int64_t)>& held, const std::string& why) {
  for (int64_t id : FindPending(data_)) {
    if (id == recording_ || !held(id)) continue;
    const ScanFolder folder = ScanFolder::For(data_, id);
    if (RestoredSinceSent(folder)) {  // Its RESTORED went out while this process was away.
      Finished(id);
      continue;
    }
    const int attempts = PendingAttempts(folder);
    if (attempts >= kMaxAttempts) {
      Park(id, "not restored after " + std::to_string(attempts) +
                   " attempts, the last ended when " + why);
      continue;
    }
    Scan scan;
    Status s = ReadScanHeader(folder.raw(), &scan);  // The decoder reads the frames as it goes.
    if (s.ok()) s = MarkPending(folder, attempts + 1);
    if (!s.ok()) {
      Park(id, "cannot process it again: " + s.message());
      continue;
    }
    node_->Log("scan " + std::to_string(id) + ": " + why + " before the scan was restored; " +
               "processing it again from " + folder.raw() + " (attempt " +
               std::to_string(attempts + 1) + " of " + std::to_string(kMaxAttempts) + ")");
    node_->Count("scans sent again");
    reached_[id] = -1;
    if (send_(id, scan).ok()) reached_[id] = std::max(reached_[id], 0);
  }
}

void Supervisor::Park(int64_t id, const std::string& why) {
  const ScanFolder folder = ScanFolder::For(data_, id);
  Finished(id);
  const Status marked = MarkFailed(folder, "parked: " + why);
  node_->Count("scans parked");
  node_->Count(counter::kScansFailed);  // Before the error goes out with the count.
  node_->Error(
      "scan " + std::to_string(id) + " failed and is parked: " + why +
          "; it is not sent again; its captures are kept in " + folder.raw() +
          " (`vellum process --scan " + folder.raw() + "` runs it by hand)" +
          (marked.ok() ? "" : " (and it could not be marked failed: " + marked.message() + ")"),
      id);
}

// The restorer wrote the scan's results after the scan was last sent down the chain.
bool Supervisor::RestoredSinceSent(const ScanFolder& folder) const {
  std::error_code a, b;
  const auto sent = fs::last_write_time(folder.pending(), a);
  const auto restored = fs::last_write_time(folder.results() + "/restored.json", b);
  return !a && !b && restored >= sent;
}

}  // namespace vellum::station
