#include "daemons/lights/relay_lights.h"

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace vellum::station {

std::vector<uint8_t> RelayCommand(int channel, bool on) {
  const uint8_t c = static_cast<uint8_t>(channel + 1), s = on ? 1 : 0;
  return {0xA0, c, s, static_cast<uint8_t>(0xA0 + c + s)};
}

RelayLights::~RelayLights() {
  if (fd_ >= 0) {
    (void)Switch(-1);  // Lights off, studio on: the station is left as it is between scans.
    close(fd_);
  }
}

Status RelayLights::Open(const std::string& device) {
  device_ = device;
  fd_ = open(device.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (fd_ < 0) {
    return Status::Error(device + ": cannot open the relay board: " + std::strerror(errno) +
                         " (is it plugged in, and may this user use it: group dialout?)");
  }
  termios tty{};
  if (tcgetattr(fd_, &tty) == 0) {  // A tty: raw bytes at the board's 9600 baud.
    cfmakeraw(&tty);
    cfsetispeed(&tty, B9600);
    cfsetospeed(&tty, B9600);
    if (tcsetattr(fd_, TCSANOW, &tty) != 0) {
      return Status::Error(device + ": cannot set 9600 baud: " + std::strerror(errno));
    }
  }
  return Switch(-1);
}

std::string RelayLights::Describe() const {
  return "relay: a serial relay board on " + device_ +
         (studio_ >= 0 ? ", the studio lamps on channel " + std::to_string(studio_) : "");
}

Status RelayLights::Send(int channel, bool on) {
  const std::vector<uint8_t> bytes = RelayCommand(channel, on);
  if (write(fd_, bytes.data(), bytes.size()) != static_cast<ssize_t>(bytes.size())) {
    return Status::Error(device_ + ": writing to the relay board failed: " + std::strerror(errno));
  }
  return Status::Ok();
}

Status RelayLights::Switch(int channel) {
  if (fd_ < 0) return Status::Error("the relay board is not open");
  // Off first, then on: two lights are never on together.
  for (int c : channels_) {
    if (c >= 0 && c != channel) {
      const Status s = Send(c, false);
      if (!s.ok()) return s;
    }
  }
  if (studio_ >= 0) {
    const Status s = Send(studio_, channel < 0);
    if (!s.ok()) return s;
  }
  if (channel >= 0) return Send(channel, true);
  return Status::Ok();
}

}  // namespace vellum::station
