// Reassembly of a chunked product (CORRESPONDENCE, POINT_CLOUD, FLAT_MESH) on a daemon's
// worker thread: every chunk is checked and copied in; a product is handed on when whole.
// When its last chunk comes with others missing, when its sender announces it sent and some are
// missing (AwaitAnnounced), or when its chunks stop coming before it is whole (the bus lost some:
// a loaded machine, this daemon paused), the missing ones are asked again on RESEND, at once and
// then every ask_after_s, and the publisher sends them again ("products
// recovered"); the loss itself is logged and counted, not an error (Node::RecoversLosses). It is
// given up, with an error naming the missing chunks ("products lost"), when the next scan's chunks
// begin, when nothing came for timeout_s (by the node's clock), or when its chunks start again
// unasked (a re-send: the product is then built from the new send alone, never from two).
#pragma once

#include <algorithm>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "station/messages.h"
#include "station/node.h"
#include "vellum/resend_request_t.hpp"
#include "vellum/scan_progress_t.hpp"

namespace vellum::station {

template <class Msg, class Product>
class Assembler {
 public:
  // Copies one chunk into the product under construction (a fresh Product{} on the first).
  using AddFn = std::function<Status(const Msg&, Product*)>;
  // The whole product, with the last chunk (for its header fields); worker thread.
  using DoneFn = std::function<void(int64_t scan_id, Product* product, const Msg& last)>;

  Assembler(Node* node, std::string channel, AddFn add, DoneFn done, double timeout_s = 10,
            double ask_after_s = 1)
      : node_(node),
        channel_(std::move(channel)),
        add_(std::move(add)),
        done_(std::move(done)),
        timeout_s_(timeout_s),
        ask_after_s_(ask_after_s) {
    node->RecoversLosses(channel_);
    node->Subscribe<Msg>(channel_, [this](const Msg& msg) {
      auto copy = std::make_shared<Msg>(msg);
      node_->Post([this, copy] { OnChunk(*copy); });
    });
  }

  // Also awaits every product its sender announces on SCAN_PROGRESS as `product` (the
  // channel's own name, or one sent after it): one of which not a chunk came (the bus lost them
  // all) is asked again whole, and given up after timeout_s; one begun and not whole (its last
  // chunks lost) has its missing chunks asked at once.
  void AwaitAnnounced(const std::string& product) {
    node_->Subscribe<scan_progress_t>(channel::kScanProgress,
                                      [this, product](const scan_progress_t& msg) {
                                        if (msg.product != product || msg.scan_id <= 0) return;
                                        const int64_t id = msg.scan_id;
                                        node_->Post([this, id] { Announced(id); });
                                      });
  }

  // Call about once a second (from the LCM thread): asks again for the chunks of a product
  // whose chunks stopped, and gives it up after timeout_s.
  void Tick() {
    node_->Post([this] {
      AskAwaited();
      const Clock::time_point now = node_->Now();
      if (chunks_.Stale(timeout_s_, now)) {
        GiveUp("after " + std::to_string(static_cast<int>(timeout_s_)) + " s");
      } else if (chunks_.Stale(ask_after_s_, now) && now - asked_ > Seconds(ask_after_s_)) {
        Ask();
      }
    });
  }

 private:
  // A product announced by its sender of which no chunk came.
  struct Awaited {
    int64_t scan_id = 0;
    Clock::time_point since, asked;
    int asks = 0;
  };

  void Announced(int64_t scan_id) {
    if (chunks_.Started() && chunks_.scan_id() == scan_id) {
      // Its sender announces it once its last chunk has gone, and chunks are handled in the
      // order they came: any still missing was lost. Asked at once, not after ask_after_s of
      // quiet: nothing else tells of a lost last chunk, and the operator is waiting.
      if (!chunks_.Complete() && asks_ == 0) Ask();
      return;
    }
    if (std::find(seen_.begin(), seen_.end(), scan_id) != seen_.end()) {
      return;  // It came.
    }
    const Clock::time_point now = node_->Now();
    awaited_.push_back({scan_id, now, now, 0});
  }

  void AskAwaited() {
    const Clock::time_point now = node_->Now();
    for (auto it = awaited_.begin(); it != awaited_.end();) {
      if (now - it->since > Seconds(timeout_s_)) {
        node_->Count(counter::kProductsLost);
        node_->Error("scan " + std::to_string(it->scan_id) + ": " + channel_ +
                         " announced by its sender and never came, asked again " +
                         std::to_string(it->asks) + " time(s); dropped",
                     it->scan_id);
        it = awaited_.erase(it);
        continue;
      }
      if (now - it->asked > Seconds(ask_after_s_)) {
        Request(it->scan_id, 0, {});  // All of it.
        node_->Count(counter::kProductsAskedAgain);
        it->asked = now;
        ++it->asks;
      }
      ++it;
    }
  }

  // Asks this channel's publisher for a scan's product again: the chunks listed, of the product
  // holding the chunk with seq `known_seq`, or (known_seq 0) the whole product.
  void Request(int64_t scan_id, int64_t known_seq, std::vector<int32_t> chunks) {
    resend_request_t ask{};
    ask.process = node_->process();
    ask.channel = channel_;
    ask.scan_id = scan_id;
    ask.known_seq = known_seq;
    ask.chunks = std::move(chunks);
    ask.nchunks = static_cast<int32_t>(ask.chunks.size());
    node_->Publish(channel::kResend, &ask);
  }

  void Ask() {
    std::vector<int32_t> missing = chunks_.MissingIndices();
    node_->Count(counter::kChunksAskedAgain, static_cast<int64_t>(missing.size()));
    Request(chunks_.scan_id(), known_seq_, std::move(missing));
    asked_ = node_->Now();
    ++asks_;
  }

  // `lost`: the bus lost it (not a send started over).
  void GiveUp(const std::string& when, bool lost = true) {
    if (lost) node_->Count(counter::kProductsLost);
    node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": " + channel_ + " incomplete (" +
                     chunks_.Missing() + ") " + when +
                     (asks_ > 0 ? ", asked again " + std::to_string(asks_) + " time(s)" : "") +
                     "; dropped",
                 chunks_.scan_id());
    StartOver();
    node_->SetState("idle");
  }

  // The first chunk of a product: named for RESEND, no longer awaited.
  void Began(const Msg& msg) {
    known_seq_ = msg.seq;
    if (std::find(seen_.begin(), seen_.end(), msg.scan_id) == seen_.end()) {
      seen_.push_back(msg.scan_id);
      if (seen_.size() > 16) seen_.erase(seen_.begin());
    }
    for (auto it = awaited_.begin(); it != awaited_.end(); ++it) {
      if (it->scan_id != msg.scan_id) continue;
      asks_ = it->asks;  // It came because it was asked.
      awaited_.erase(it);
      break;
    }
  }

  void StartOver() {
    chunks_.Reset();
    product_ = Product{};
    seq_of_.clear();
    asks_ = 0;
    asked_ = {};
  }

  // A chunk this receiver has, heard again with its seq: sent again for another receiver's
  // RESEND (every receiver on the channel hears it), or asked by this one and late. Not a new
  // send, which numbers its chunks anew.
  bool HeardBefore(const Msg& msg) const {
    if (chunks_.Has(msg.scan_id, msg.chunk_index) && !chunks_.Complete() &&
        seq_of_[static_cast<size_t>(msg.chunk_index)] == msg.seq) {
      return true;
    }
    return std::any_of(whole_.begin(), whole_.end(), [&](const Whole& w) {
      return w.scan_id == msg.scan_id && msg.seq >= w.first_seq && msg.seq <= w.last_seq;
    });
  }

  void OnChunk(const Msg& msg) {
    if (HeardBefore(msg)) {
      node_->Count("chunks heard again");
      return;
    }
    if (!chunks_.Complete() && chunks_.Has(msg.scan_id, msg.chunk_index)) {
      // A chunk of the product being built comes again before it is whole: its sender started
      // it over (a daemon restarted mid-send, a scan sent again). What came before is dropped,
      // so a product is never made of two sends' chunks.
      GiveUp("when it was sent again (chunk " + std::to_string(msg.chunk_index) +
                 " came twice); starting over with the new send",
             /*lost=*/false);
    }
    if (chunks_.Started() && (chunks_.scan_id() != msg.scan_id || chunks_.Complete())) {
      if (!chunks_.Complete()) GiveUp("when scan " + std::to_string(msg.scan_id) + " began");
      StartOver();
    }
    Status s = chunks_.Add(msg.scan_id, msg.chunk_index, msg.chunk_count, node_->Now());
    if (s.ok() && chunks_.received() == 1) {
      Began(msg);
      seq_of_.assign(static_cast<size_t>(msg.chunk_count), 0);
    }
    if (s.ok()) seq_of_[static_cast<size_t>(msg.chunk_index)] = msg.seq;
    if (s.ok()) s = add_(msg, &product_);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(msg.scan_id) + ": " + channel_ + ": " + s.message(),
                   msg.scan_id);
      return;
    }
    if (!chunks_.Complete()) {
      // Chunks go in order: the last one come with others missing means those were lost. They
      // are asked at once, not after ask_after_s of quiet: the operator is waiting.
      if (msg.chunk_index == msg.chunk_count - 1 && asks_ == 0) Ask();
      return;
    }
    whole_.push_back({msg.scan_id, *std::min_element(seq_of_.begin(), seq_of_.end()),
                      *std::max_element(seq_of_.begin(), seq_of_.end())});
    if (whole_.size() > 4) whole_.erase(whole_.begin());
    if (asks_ > 0) {
      node_->Count("products recovered");
      node_->Log("scan " + std::to_string(msg.scan_id) + ": " + channel_ +
                 " whole again after asking " + std::to_string(asks_) + " time(s)");
    }
    done_(msg.scan_id, &product_, msg);
  }

  Node* node_;
  std::string channel_;
  AddFn add_;
  DoneFn done_;
  double timeout_s_, ask_after_s_;
  // Worker thread only:
  ChunkSet chunks_;
  Product product_;
  int64_t known_seq_ = 0;  // The seq of a chunk that came (names the product on RESEND).
  int asks_ = 0;           // Times the missing chunks were asked again.
  Clock::time_point asked_;
  std::vector<Awaited> awaited_;  // Announced, not a chunk yet.
  std::vector<int64_t> seen_;     // The last scans of which a chunk came, oldest first.
  std::vector<int64_t> seq_of_;   // Each chunk's seq, of the product being built.
  // The last products made whole: a publisher numbers a product's chunks in a row, so its
  // chunks' seqs span first_seq..last_seq.
  struct Whole {
    int64_t scan_id, first_seq, last_seq;
  };
  std::vector<Whole> whole_;
};

}  // namespace vellum::station
