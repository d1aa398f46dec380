// Reassembly of a chunked product (CORRESPONDENCE, POINT_CLOUD, FLAT_MESH) on a daemon's
// worker thread: every chunk is checked and copied in; a product is handed on when whole, and
// given up with an error naming the missing chunks when the next scan's chunks begin, when its
// chunks stop coming, or when they start again (a re-send: the product is then built from the
// new send alone, never from two).
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

template <class Msg, class Product>
class Assembler {
 public:
  // Copies one chunk into the product under construction (a fresh Product{} on the first).
  using AddFn = std::function<Status(const Msg&, Product*)>;
  // The whole product, with the last chunk (for its header fields); worker thread.
  using DoneFn = std::function<void(int64_t scan_id, Product* product, const Msg& last)>;

  Assembler(Node* node, std::string channel, AddFn add, DoneFn done, double timeout_s = 10)
      : node_(node),
        channel_(std::move(channel)),
        add_(std::move(add)),
        done_(std::move(done)),
        timeout_s_(timeout_s) {
    node->Subscribe<Msg>(channel_, [this](const Msg& msg) {
      auto copy = std::make_shared<Msg>(msg);
      node_->Post([this, copy] { OnChunk(*copy); });
    });
  }

  // Call about once a second (from the LCM thread): gives up a product whose chunks stopped.
  void Tick() {
    node_->Post([this] {
      if (!chunks_.Stale(timeout_s_)) return;
      GiveUp("after " + std::to_string(static_cast<int>(timeout_s_)) + " s");
    });
  }

 private:
  void GiveUp(const std::string& when) {
    node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": " + channel_ + " incomplete (" +
                     chunks_.Missing() + ") " + when + "; dropped",
                 chunks_.scan_id());
    chunks_.Reset();
    product_ = Product{};
    node_->SetState("idle");
  }

  void OnChunk(const Msg& msg) {
    if (!chunks_.Complete() && chunks_.Has(msg.scan_id, msg.chunk_index)) {
      // A chunk of the product being built comes again before it is whole: its sender started
      // it over (a daemon restarted mid-send, a scan sent again). What came before is dropped,
      // so a product is never made of two sends' chunks.
      GiveUp("when it was sent again (chunk " + std::to_string(msg.chunk_index) +
             " came twice); starting over with the new send");
    }
    if (chunks_.Started() && (chunks_.scan_id() != msg.scan_id || chunks_.Complete())) {
      if (!chunks_.Complete()) GiveUp("when scan " + std::to_string(msg.scan_id) + " began");
      chunks_.Reset();
      product_ = Product{};
    }
    Status s = chunks_.Add(msg.scan_id, msg.chunk_index, msg.chunk_count);
    if (s.ok()) s = add_(msg, &product_);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(msg.scan_id) + ": " + channel_ + ": " + s.message(),
                   msg.scan_id);
      return;
    }
    if (chunks_.Complete()) done_(msg.scan_id, &product_, msg);
  }

  Node* node_;
  std::string channel_;
  AddFn add_;
  DoneFn done_;
  double timeout_s_;
  ChunkSet chunks_;  // Worker thread only.
  Product product_;  // Worker thread only.
};

}  // namespace vellum::station
