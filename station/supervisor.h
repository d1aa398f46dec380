// The station's supervisor: sees every scan from its recording to RESTORED, so that no scan is
// lost when a processing daemon dies holding it. It lives in vellum-decoder (which holds every
// scan's captures and can send a scan down the chain again), on the decoder's worker thread.
//
// It watches, on the bus:
//  - SCAN_PROGRESS: how far down the chain each scan has come (the last daemon that handed it
//    on, station/chain.h);
//  - the processing daemons' STATUS heartbeats: a new pid is a restart; an error a daemon
//    reports about a scan ends that scan (the operator sees the error), unless the daemon lost
//    the scan's product on the bus (its "products lost" counter rose with the error): that scan
//    is sent again from disk, as for a restart;
//  - RESTORED: the scan is done.
// It keeps, on disk, the ledger of scans recorded and not yet restored: <data>/scan-<id>/pending,
// holding how many times the scan was sent down the chain. It outlives every process.
//
// When a processing daemon restarts, the scans it held, or that were on their way to it (handed
// on by the daemon before it and not yet by itself), are sent again from disk: a scan already
// past it is not. When the decoder itself starts, once every processing daemon is heard, every
// scan in the ledger that no one holds is sent again (the station stopped); one this process
// sent has its last product announced again instead (a daemon that had not started asks for
// it). A scan is sent at most kMaxAttempts times: one that lost its daemon twice (a scan that
// crashes or hangs a daemon), or whose captures cannot be read back, is parked: out of the
// ledger, marked failed on disk (raw/failed.txt, with the reason), reported with a message
// naming its raw captures, and never sent again, even after a restart.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/scan.h"
#include "station/node.h"
#include "station/scan_store.h"
#include "vellum/status_t.hpp"

namespace vellum::station {

// The ledger: marks a scan pending with the times it was sent (written whole or not at all).
[[nodiscard]] Status MarkPending(const ScanFolder& folder, int attempts);
int PendingAttempts(const ScanFolder& folder);  // 0: not pending.
void ClearPending(const ScanFolder& folder);
std::vector<int64_t> FindPending(const std::string& data_dir);  // Ascending.

// Announces on SCAN_PROGRESS that this process has handed `scan_id` on with `product`, then
// counts it in `counter` (when one is named). In that order, so that no status (a heartbeat may
// go out between the two) counts a scan as handed on before its announcement is on the bus: a
// daemon started by whoever waited for that count (systemd, a test) cannot hear it, and so cannot
// take the scan up from the announcement instead of from the supervisor's ledger.
void AnnounceHandedOn(Node* node, int64_t scan_id, const std::string& product,
                      const std::string& counter = "");

class Supervisor {
 public:
  static constexpr int kMaxAttempts = 2;

  // Sends a scan down the chain (the decoder decodes it and publishes its products); called on
  // the worker thread. A failure is reported by the sender.
  using Send = std::function<Status(int64_t scan_id, const Scan& scan)>;

  Supervisor(Node* node, std::string data_dir, Send send);

  // Worker thread. A scan is recorded whole: it enters the ledger, and is sent (first attempt).
  // False when it could not be marked (the error is reported).
  bool Recorded(int64_t scan_id, const Scan& scan);
  // Worker thread. A scan failed with a reported error (`why`): it leaves the ledger, and is
  // marked failed on disk.
  void Failed(int64_t scan_id, const std::string& why);
  // Worker thread. The scan being recorded (0: none): never sent again from under the recorder.
  void Recording(int64_t scan_id) { recording_ = scan_id; }
  // Worker thread. Whether the restorer wants the projector's light (counter::kLightWanted) in
  // the products: true until a restorer's status says otherwise.
  bool LightWanted() const { return light_wanted_; }

 private:
  struct Daemon {
    int32_t pid = 0;
    int64_t error_utime = -1;   // -1: no status yet (its old errors are not news).
    int64_t products_lost = 0;  // Its "products lost" counter (the bus lost one, asked in vain).
  };

  void OnStatus(const status_t& msg);
  void Finished(int64_t scan_id);
  // Gives a pending scan up for good (see above); `why` names what happened to it.
  void Park(int64_t scan_id, const std::string& why);
  // Sends again every pending scan for which `held` holds; `why` ends up in the log.
  void SendAgain(const std::function<bool(int64_t)>& held, const std::string& why);
  bool RestoredSinceSent(const ScanFolder& folder) const;

  Node* node_;
  std::string data_;
  Send send_;
  // Worker thread only (every handler posts its work there):
  std::map<std::string, Daemon> daemons_;  // The processing daemons after the decoder.
  std::map<int64_t, int> reached_;         // Scan -> chain index of the last to hand it on.
  bool light_wanted_ = true;
  bool sent_at_start_ = false;
  int64_t recording_ = 0;
};

}  // namespace vellum::station
