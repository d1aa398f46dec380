// The lights node on an in-process bus: with the relay backend on a real serial line (a pty the
// test reads as the relay board would), a light is switched on alone (the studio lamps off) and
// answered with LIGHT_ON, and switched off when its capture comes, or when no capture comes
// within max_on; a request for a light the station does not have is refused. With the manual
// backend the operator is prompted instead.
#include "daemons/lights/lights_node.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <pty.h>
#include <unistd.h>

#include <set>

#include "daemons/lights/relay_lights.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/testing.h"

namespace vellum::station {
namespace {

using testing::MemqBus;

// The relay board's end of the serial line.
class Board {
 public:
  Board() {
    EXPECT_EQ(openpty(&master_, &slave_, name_, nullptr, nullptr), 0);
    fcntl(master_, F_SETFL, O_NONBLOCK);
  }
  ~Board() {
    close(master_);
    close(slave_);
  }
  std::string device() const { return name_; }
  // Every command received so far, as (channel, on) pairs; a malformed one fails the test.
  std::vector<std::pair<int, bool>> Commands() {
    uint8_t buffer[256];
    ssize_t n;
    while ((n = read(master_, buffer, sizeof(buffer))) > 0)
      bytes_.insert(bytes_.end(), buffer, buffer + n);
    std::vector<std::pair<int, bool>> out;
    for (size_t k = 0; k + 4 <= bytes_.size(); k += 4) {
      EXPECT_EQ(bytes_[k], 0xA0);
      EXPECT_EQ(static_cast<uint8_t>(bytes_[k] + bytes_[k + 1] + bytes_[k + 2]), bytes_[k + 3]);
      out.emplace_back(bytes_[k + 1] - 1, bytes_[k + 2] == 1);
    }
    return out;
  }
  // Which channels are on after every command so far.
  std::set<int> On() {
    std::set<int> on;
    for (const auto& [channel, state] : Commands()) {
      if (state) {
        on.insert(channel);
      } else {
        on.erase(channel);
      }
    }
    return on;
  }

 private:
  int master_ = -1, slave_ = -1;
  char name_[256] = {0};
  std::vector<uint8_t> bytes_;
};

LightsNodeOptions StationWithThreeLights() {
  LightsNodeOptions options;
  for (const char* name : {"raking-000", "raking-120", "uv"}) {
    ScanLight light;
    light.name = name;
    if (name[0] == 'r') light.direction = cv::Vec3d(0.8, 0.0, 0.6);
    options.lights.lights.push_back(light);
  }
  options.lights.channels = {1, 2, 3};
  options.lights.studio_channel = 0;
  return options;
}

light_t Request(const LightsNodeOptions& options, int index, int64_t scan_id = 40) {
  light_t m{};
  m.scan_id = scan_id;
  m.session = 7;
  m.index = index;
  m.light_count = static_cast<int32_t>(options.lights.lights.size());
  if (index >= 0) m.light = ToMessage(options.lights.lights[index]);
  return m;
}

// The camera's capture under light `index` of scan 40 (session 7, ten patterns before it).
capture_t CaptureUnder(int index) {
  capture_t c{};
  c.scan_id = 40;
  c.session = 7;
  c.pattern_count = 10;
  c.pattern_index = 10 + index;
  return c;
}

TEST(LightsNodeTest, ARelaySwitchesEachLightOnAloneAndOffWhenItsCaptureComes) {
  MemqBus bus;
  Board board;
  LightsNodeOptions options = StationWithThreeLights();
  auto relay =
      std::make_unique<RelayLights>(options.lights.channels, options.lights.studio_channel);
  ASSERT_TRUE(relay->Open(board.device()).ok());
  EXPECT_EQ(board.On(), (std::set<int>{0})) << "at start: the studio lamps on, the others off";
  Node node("vellum-lights", &bus.lcm(), &bus.clock());
  LightsNode lights(&node, std::move(relay), options);
  bus.AddTick([&] { lights.Tick(); });
  auto on = bus.Record<light_t>(channel::kLightOn);
  light_t request = Request(options, 1);
  bus.probe().Publish(channel::kLightRequest, &request);
  ASSERT_TRUE(bus.RunUntil([&] { return on->size() == 1; }));
  EXPECT_EQ(on->front().index, 1);
  EXPECT_EQ(on->front().light.name, "raking-120");
  EXPECT_EQ(on->front().source, "relay");
  EXPECT_EQ(on->front().session, 7);
  EXPECT_EQ(board.On(), (std::set<int>{2})) << "light 1 alone, the studio lamps off";
  // A capture of another index leaves it on; its own turns it off, the studio lamps on again.
  capture_t c = CaptureUnder(0);
  bus.probe().Publish(channel::kCapture, &c);
  c = CaptureUnder(1);
  bus.probe().Publish(channel::kCapture, &c);
  ASSERT_TRUE(bus.RunUntil([&] { return board.On() == std::set<int>{0}; }));
  EXPECT_EQ(node.Counter("lights switched"), 1);
}

TEST(LightsNodeTest, ALightNoCaptureComesForGoesOffAndAStrangeRequestIsRefused) {
  MemqBus bus;
  Board board;
  LightsNodeOptions options = StationWithThreeLights();
  auto relay =
      std::make_unique<RelayLights>(options.lights.channels, options.lights.studio_channel);
  ASSERT_TRUE(relay->Open(board.device()).ok());
  Node node("vellum-lights", &bus.lcm(), &bus.clock());
  LightsNode lights(&node, std::move(relay), options);
  bus.AddTick([&] { lights.Tick(); });
  bus.Watch("vellum-lights");
  light_t strange = Request(options, 0);
  strange.light.name = "infrared";
  bus.probe().Publish(channel::kLightRequest, &strange);
  EXPECT_TRUE(bus.WaitForError("vellum-lights", "'infrared' of 3: not one of this station's"));
  EXPECT_EQ(board.On(), (std::set<int>{0}));
  light_t uv = Request(options, 2);
  bus.probe().Publish(channel::kLightRequest, &uv);
  ASSERT_TRUE(bus.RunUntil([&] { return board.On() == std::set<int>{3}; }));
  // On for its longest (max_on, a minute) by the node's clock, and no longer.
  bus.StepFor(59);
  EXPECT_EQ(board.On(), (std::set<int>{3}));
  EXPECT_TRUE(bus.StepUntil(
      [&] {
        return bus.Status("vellum-lights")
                   .last_error.find("the light 'uv' was on for 60.0 s with no capture") !=
               std::string::npos;
      },
      0.5, 2))
      << bus.Status("vellum-lights").last_error;
  EXPECT_EQ(board.On(), (std::set<int>{0}));
}

TEST(LightsNodeTest, TheManualBackendPromptsTheOperator) {
  MemqBus bus;
  LightsNodeOptions options = StationWithThreeLights();
  Node node("vellum-lights", &bus.lcm(), &bus.clock());
  LightsNode lights(&node, std::make_unique<ManualLights>(), options);
  auto prompts = bus.Record<light_t>(channel::kLightPrompt);
  auto on = bus.Record<light_t>(channel::kLightOn);
  light_t request = Request(options, 0);
  bus.probe().Publish(channel::kLightRequest, &request);
  ASSERT_TRUE(bus.RunUntil([&] { return prompts->size() == 1; }));
  EXPECT_EQ(prompts->front().index, 0);
  EXPECT_NE(prompts->front().text.find("'raking-000'"), std::string::npos) << prompts->front().text;
  EXPECT_NE(prompts->front().text.find("press L in the viewer"), std::string::npos);
  EXPECT_TRUE(on->empty()) << "the operator answers, not the node";
  // Its capture asks nothing (the next light's prompt would say "nothing else"); the scan's end
  // asks for the lights off.
  capture_t c = CaptureUnder(0);
  bus.probe().Publish(channel::kCapture, &c);
  light_t off = Request(options, -1);
  bus.probe().Publish(channel::kLightRequest, &off);
  ASSERT_TRUE(bus.RunUntil([&] { return prompts->size() >= 2; }));
  EXPECT_EQ(prompts->size(), 2u);
  EXPECT_EQ(prompts->back().index, -1);
  EXPECT_NE(prompts->back().text.find("studio lamps on"), std::string::npos);
}

TEST(LightsNodeOptions, NonsenseIsRefusedByName) {
  LightsNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.max_on = std::chrono::duration<double>(0);
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("max_on"), std::string::npos) << why;
}

}  // namespace
}  // namespace vellum::station
