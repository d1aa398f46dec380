// vellum-lights' node: the station's extra lights. On LIGHT_REQUEST(k) from the
// projector (of this station, a scan with its session, k naming the station's light k) it
// switches light k on and every other off (and the studio lamps off), waits the lamp's settle
// time and publishes LIGHT_ON(k); with the manual backend it publishes LIGHT_PROMPT(k) instead,
// and the operator's LIGHT_ON comes from the viewer. The light goes off again when the camera's
// CAPTURE of it comes, on LIGHT_REQUEST(-1), or after `max_on` at the latest (UV light harms
// what it lights: never left on by a scan that died).
#pragma once

#include <chrono>
#include <memory>

#include "daemons/lights/lights.h"
#include "io/scan_io.h"
#include "station/node.h"
#include "vellum/capture_t.hpp"
#include "vellum/light_t.hpp"

namespace vellum::station {

struct LightsNodeOptions {
  StationLights lights;                 // The station's lights file.
  std::chrono::milliseconds settle{0};  // After switching on, before LIGHT_ON (lamps warm up).
  std::chrono::duration<double> max_on{60.0};  // The longest a light stays on.
  bool Check(std::string* why) const;
};

class LightsNode {
 public:
  LightsNode(Node* node, std::unique_ptr<Lights> lights, const LightsNodeOptions& options);
  // On the LCM thread, often: the max_on guard.
  void Tick();

 private:
  void OnRequest(const light_t& m);
  void OnCapture(const capture_t& m);
  void AllOff(const std::string& why);

  Node* node_;
  std::unique_ptr<Lights> lights_;
  LightsNodeOptions options_;
  // LCM thread only: the light that is on (-1 none), for which scan and session.
  int on_ = -1;
  bool by_hand_ = false;  // The operator switched a light of this scan (asked to end it).
  int64_t scan_id_ = 0, session_ = 0;
  Clock::time_point on_since_;
};

}  // namespace vellum::station
