// The station's extra lights on a USB relay board of the common serial kind (CH340 "LCUS"
// boards, 1 to 8 channels, 9600 baud): each command is four bytes, 0xA0, the channel (1-based),
// the state (1 on, 0 off) and their sum modulo 256. Channels are the lights file's `channel`
// (0-based here, as in the file). The studio lamps, when on a channel of their own, go off while
// an extra light is on.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "daemons/lights/lights.h"

namespace vellum::station {

// The four bytes that set relay `channel` (0-based) on or off.
std::vector<uint8_t> RelayCommand(int channel, bool on);

class RelayLights : public Lights {
 public:
  // `channels`: every light's channel; `studio_channel`: the studio lamps' (-1: none).
  RelayLights(std::vector<int> channels, int studio_channel)
      : channels_(std::move(channels)), studio_(studio_channel) {}
  ~RelayLights() override;
  // Opens the serial device (a tty: raw, 9600 8N1; or any file a test reads back). Errors name
  // the device.
  Status Open(const std::string& device);
  std::string Describe() const override;
  std::string Source() const override { return "relay"; }
  Status Switch(int channel) override;

 private:
  Status Send(int channel, bool on);
  std::vector<int> channels_;
  int studio_ = -1;
  std::string device_;
  int fd_ = -1;
};

}  // namespace vellum::station
