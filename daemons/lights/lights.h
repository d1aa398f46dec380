// What the lights daemon needs of the station's extra lights: switch one on and every
// other off, or all off. A relay board on a serial line (relay_lights.h), the virtual gantry's
// lights (sim: the sim camera renders the light the frame names) and the operator's hands
// (manual: prompted in the viewer) implement it; the node sees only this interface.
#pragma once

#include <string>

#include "core/common/status.h"

namespace vellum::station {

class Lights {
 public:
  virtual ~Lights() = default;
  // One line for the log: what switches the lights.
  virtual std::string Describe() const = 0;
  // Who answers LIGHT_ON: "relay", "sim"; "" when the operator switches by hand (the node
  // prompts, and the viewer answers).
  virtual std::string Source() const = 0;
  // Light `channel` on and every other extra light off, the studio lamps off; channel -1: every
  // extra light off and the studio lamps on again.
  virtual Status Switch(int channel) = 0;
};

// Nothing physical: the virtual gantry renders the light the frame names. Answers at once.
class SimLights : public Lights {
 public:
  std::string Describe() const override { return "sim: the virtual gantry's lights"; }
  std::string Source() const override { return "sim"; }
  Status Switch(int) override { return Status::Ok(); }
};

// The operator switches each light by hand when the viewer asks.
class ManualLights : public Lights {
 public:
  std::string Describe() const override {
    return "manual: the operator switches each light when the viewer asks";
  }
  std::string Source() const override { return ""; }
  Status Switch(int) override { return Status::Ok(); }
};

}  // namespace vellum::station
