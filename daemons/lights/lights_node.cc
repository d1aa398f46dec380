#include "daemons/lights/lights_node.h"

#include <thread>

#include "core/common/text.h"
#include "station/messages.h"

namespace vellum::station {

namespace {
constexpr char kScanOver[] = "the scan is over";
}  // namespace

bool LightsNodeOptions::Check(std::string* why) const {
  if (settle.count() < 0 || !(max_on.count() > 0)) {
    *why = "lights: settle must be >= 0 and max_on > 0";
    return false;
  }
  return true;
}

LightsNode::LightsNode(Node* node, std::unique_ptr<Lights> lights, const LightsNodeOptions& options)
    : node_(node), lights_(std::move(lights)), options_(options) {
  node->Subscribe<light_t>(channel::kLightRequest, [this](const light_t& m) { OnRequest(m); });
  node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& m) { OnCapture(m); });
  std::string names;
  for (const ScanLight& l : options_.lights.lights) names += (names.empty() ? "" : ", ") + l.name;
  node->Log(lights_->Describe() + "; lights " + names);
  node->SetState("idle");
}

void LightsNode::Tick() {
  // The operator's lights are theirs to switch.
  if (on_ >= 0 && !lights_->Source().empty() && node_->Now() - on_since_ > options_.max_on) {
    const std::string name = options_.lights.lights[on_].name;
    const int64_t scan = scan_id_;
    AllOff("");
    node_->Error("the light '" + name + "' was on for " + Fixed(options_.max_on.count(), 1) +
                     " s with no capture of it: switched off",
                 scan);
  }
}

void LightsNode::AllOff(const std::string& why) {
  const Status s = lights_->Switch(-1);
  if (!s.ok()) node_->Error("switching the lights off failed: " + s.message(), scan_id_);
  if (on_ >= 0 && !why.empty()) {
    node_->Log("the light '" + options_.lights.lights[on_].name + "' off: " + why);
  }
  // By hand: the operator is asked once the scan is over (between lights, the next light's prompt
  // says that nothing else may be on).
  if (by_hand_ && why == kScanOver) {
    by_hand_ = false;
    light_t prompt{};
    prompt.scan_id = scan_id_;
    prompt.session = session_;
    prompt.index = -1;
    prompt.light_count = static_cast<int32_t>(options_.lights.lights.size());
    prompt.text = "Switch the extra light off and the studio lamps on again.";
    node_->Publish(channel::kLightPrompt, &prompt);
  }
  on_ = -1;
  node_->SetState("idle", scan_id_);
}

void LightsNode::OnRequest(const light_t& m) {
  const int count = static_cast<int>(options_.lights.lights.size());
  const std::string where = "scan " + std::to_string(m.scan_id) + ": LIGHT_REQUEST ";
  if (m.scan_id <= 0 || m.session <= 0) {
    return node_->Error(where + "without a scan and its session; ignored");
  }
  if (m.index == -1) {
    if (m.scan_id == scan_id_ && m.session == session_) AllOff(kScanOver);
    return;
  }
  if (m.light_count != count || m.index < 0 || m.index >= count ||
      m.light.name != options_.lights.lights[m.index].name) {
    return node_->Error(where + "for light " + std::to_string(m.index) + " '" +
                            Printable(m.light.name, 40) + "' of " + std::to_string(m.light_count) +
                            ": not one of this station's lights (its lights file lists " +
                            std::to_string(count) +
                            "; do the projector and vellum-lights read "
                            "the same file?)",
                        m.scan_id);
  }
  const ScanLight& light = options_.lights.lights[m.index];
  const int channel = options_.lights.channels[m.index];
  scan_id_ = m.scan_id;
  session_ = m.session;
  const Status s = lights_->Switch(channel);
  if (!s.ok()) {
    AllOff("");
    return node_->Error(where + "switching on '" + light.name + "' failed: " + s.message(),
                        m.scan_id);
  }
  on_ = m.index;
  on_since_ = node_->Now();
  node_->Count("lights switched");
  light_t reply = m;
  reply.utime = 0;
  if (lights_->Source().empty()) {
    reply.text = "Switch on the light '" + light.name + "' and nothing else (studio lamps off" +
                 (light.directed() ? ", the lamp where the lights file says" : "") +
                 "); then press L in the viewer.";
    by_hand_ = true;
    node_->SetState("waiting", m.scan_id, "for the operator to switch on '" + light.name + "'");
    node_->Publish(channel::kLightPrompt, &reply);
    return;
  }
  std::this_thread::sleep_for(options_.settle);
  reply.source = lights_->Source();
  node_->SetState("on", m.scan_id, "'" + light.name + "' on");
  node_->Publish(channel::kLightOn, &reply);
}

void LightsNode::OnCapture(const capture_t& m) {
  if (on_ < 0 || m.scan_id != scan_id_ || m.session != session_ ||
      m.pattern_index != m.pattern_count + on_) {
    return;
  }
  AllOff("captured");
}

}  // namespace vellum::station
