#include "daemons/viewer/viewer_node.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "station/chain.h"
#include "station/messages.h"

namespace vellum::station {

bool ViewerNodeOptions::Check(std::string* why) const {
  if (!session_file.empty() && std::filesystem::is_directory(session_file)) {
    *why = "viewer: session_file " + session_file + " is a folder";
    return false;
  }
  return true;
}

bool ActionForKey(SDL_Keycode key, bool form_open, ViewerState::Action* action) {
  using A = ViewerState::Action;
  if (form_open) {  // The form has the keyboard: letters arrive as text.
    switch (key) {
      case SDLK_TAB:
      case SDLK_DOWN:
        *action = A::kFieldNext;
        return true;
      case SDLK_UP:
        *action = A::kFieldBack;
        return true;
      case SDLK_BACKSPACE:
        *action = A::kBackspace;
        return true;
      case SDLK_RETURN:
      case SDLK_KP_ENTER:
      case SDLK_ESCAPE:
        *action = A::kFormDone;
        return true;
      case SDLK_SPACE:
      case SDLK_LEFT:
      case SDLK_RIGHT:
        *action = A::kChoose;
        return true;
      default:
        return false;
    }
  }
  switch (key) {
    case SDLK_q:
    case SDLK_ESCAPE:
      *action = A::kQuit;
      return true;
    case SDLK_s:
    case SDLK_RETURN:
    case SDLK_KP_ENTER:
      *action = A::kScan;
      return true;
    case SDLK_y:
      *action = A::kConfirm;
      return true;
    case SDLK_c:
      *action = A::kSheet;
      return true;
    case SDLK_o:
      *action = A::kObject;
      return true;
    case SDLK_h:
      *action = A::kClearHint;
      return true;
    case SDLK_l:
      *action = A::kLightDone;
      return true;
    case SDLK_z:
      *action = A::kZoom;
      return true;
    case SDLK_e:
      *action = A::kEdit;
      return true;
    case SDLK_u:
      *action = A::kUndo;
      return true;
    case SDLK_LEFT:
      *action = A::kPrevious;
      return true;
    case SDLK_RIGHT:
      *action = A::kNext;
      return true;
    default:
      return false;
  }
}

ViewerNode::ViewerNode(Node* node, std::unique_ptr<display::Window> window,
                       const ViewerNodeOptions& options)
    : node_(node), window_(std::move(window)), options_(options) {
  LoadSession();
  // Text input only while the form is open: a key that opens it (e) must not also type itself
  // into it, as SDL sends both a key and its text while text input is on.
  window_->TextInput(false);
  node->Subscribe<image_t>(channel::kPreview, [this](const image_t& m) {
    cv::Mat image;
    const Status s = FromMessage(m, &image);
    if (!s.ok()) return node_->Error("PREVIEW: " + s.message());
    state_.OnPreview(image, node_->Now(), /*of_capture=*/m.scan_id != 0);
  });
  node->Subscribe<image_t>(channel::kPreviewFocus, [this](const image_t& m) {
    cv::Mat image;
    const Status s = FromMessage(m, &image);
    if (!s.ok()) return node_->Error("PREVIEW_FOCUS: " + s.message());
    state_.OnFocus(image);
    operator_waits_ = true;
  });
  node->Subscribe<pattern_shown_t>(channel::kPatternShown,
                                   [this](const pattern_shown_t& m) { state_.OnPatternShown(m); });
  node->Subscribe<light_t>(channel::kLightPrompt,
                           [this](const light_t& m) { state_.OnLightPrompt(m); });
  node->Subscribe<light_t>(channel::kLightOn, [this](const light_t& m) { state_.OnLightOn(m); });
  auto on_status = [this](const status_t& m) { state_.OnStatus(m, node_->Now()); };
  node->Subscribe<status_t>(StatusChannel("vellum-lights"), on_status);
  for (const char* process : kGantry) node->Subscribe<status_t>(StatusChannel(process), on_status);
  for (const ChainLink& link : kChain) {
    node->Subscribe<status_t>(StatusChannel(link.process), on_status);
  }
  node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& m) {
    cv::Mat preview;
    const Status s = FromMessage(m.preview, &preview);
    if (!s.ok()) {
      node_->Error("RESTORED of scan " + std::to_string(m.scan_id) + ": preview: " + s.message(),
                   m.scan_id);
    }
    state_.OnRestored(m, preview, /*read_pictures=*/false);  // Read once the page is drawn.
  });
}

void ViewerNode::Tick() {
  std::vector<display::Window::Input> input;
  if (!window_->Poll(&input)) node_->Stop();
  for (const display::Window::Input& in : input) {
    if (in.mouse != display::Window::Input::Mouse::kNone) {
      OnMouse(in);
    } else if (in.key != 0) {
      OnKey(in.key);
    } else {
      state_.Type(in.text);
    }
  }
  // Drawn four times a second of real time (the statuses, the progress, the live view at 2 Hz),
  // for it shares the cores with the chain; a restored page at once, for the operator waits for
  // it; what the operator does (a key, the mouse) and the focus view (a hand on the lens) at up
  // to ten times a second. What it shows is as of the node's clock (a camera silent for 2 s, a
  // daemon for 3 s).
  const bool new_page = !state_.results().empty() && state_.results().back().scan_id != shown_;
  operator_waits_ = operator_waits_ || !input.empty();
  const auto real = std::chrono::steady_clock::now();
  const bool due = real >= next_draw_ || (operator_waits_ && real >= last_draw_ + kQuickest);
  if (!due && !new_page) return;
  last_draw_ = real;
  next_draw_ = real + kPace;
  operator_waits_ = false;
  window_->Show(DrawViewer(state_, window_->size(), node_->Now(), &layout_));
  // A restored page newly on the screen: its scan goes on the status (scan_id), which is when
  // the operator sees it (bench/station_bench times it).
  if (new_page) {
    shown_ = state_.results().back().scan_id;
    node_->Count("restored pages shown");
    node_->SetState("idle", shown_, readiness_);
  }
  // The report's pictures beside the page, read once it is on the screen, and drawn at the next
  // tick.
  if (state_.ReadPendingPictures()) next_draw_ = real;
  SaveSessionAndReadiness();
}

void ViewerNode::LoadSession() {
  saved_session_ = state_.SessionJson();
  const std::string& file = options_.session_file;
  if (file.empty() || !std::filesystem::exists(file)) return;
  std::ifstream in(file);
  std::stringstream text;
  text << in.rdbuf();
  std::string why;
  if (!in || !state_.LoadSession(text.str(), &why)) {
    // Set aside under a name of its own (an earlier one set aside is kept too).
    std::string aside = file + ".bad";
    for (int k = 1; std::filesystem::exists(aside); ++k) aside = file + ".bad." + std::to_string(k);
    std::error_code ec;
    std::filesystem::rename(file, aside, ec);
    node_->Error("session " + file + " not taken up (" + (in ? why : "cannot be read") +
                 "); set aside as " + aside + ", starting afresh");
    return;
  }
  saved_session_ = state_.SessionJson();
  node_->Log("session taken up from " + file + ": next scan " +
             DescribeIdentity(state_.next_identity()));
}

void ViewerNode::SaveSessionAndReadiness() {
  const std::string refused = state_.Refusal(node_->Now());
  const std::string readiness = refused.empty() ? "ready to scan" : "cannot scan: " + refused;
  if (readiness != readiness_ && !state_.editing()) {
    readiness_ = readiness;
    node_->SetState("idle", shown_, readiness);
  }
  const std::string& file = options_.session_file;
  if (file.empty()) return;
  const std::string session = state_.SessionJson();
  if (session == saved_session_) return;
  // Said once per change of the session, not at every draw, when it cannot be written.
  saved_session_ = session;
  const std::string part = file + ".part";
  {
    std::ofstream out(part, std::ios::trunc);
    out << session;
    if (!out.flush()) return node_->Error("cannot write the session to " + part);
  }
  std::error_code ec;
  std::filesystem::rename(part, file, ec);
  if (ec) node_->Error("cannot write the session to " + file + ": " + ec.message());
}

void ViewerNode::OnKey(SDL_Keycode key) {
  ViewerState::Action action;
  if (ActionForKey(key, state_.editing(), &action)) Do(action);
}

void ViewerNode::Do(ViewerState::Action action) {
  const bool was_editing = state_.editing();
  ViewerState::Command c = state_.Act(action, NowUtime(), node_->Now());
  switch (c.kind) {
    case ViewerState::Command::Kind::kQuit:
      node_->Stop();
      break;
    case ViewerState::Command::Kind::kRequestScan:
      node_->Publish(channel::kScanRequest, &c.request);
      break;
    case ViewerState::Command::Kind::kLightOn:
      node_->Publish(channel::kLightOn, &c.light);
      break;
    case ViewerState::Command::Kind::kNone:
      break;
  }
  if (state_.editing() == was_editing) return;
  window_->TextInput(state_.editing());
  if (state_.editing()) {
    node_->SetState("editing", 0, "the next scan's identity");  // The form has the keyboard.
  } else {
    readiness_.clear();  // Said again at the next draw.
    node_->SetState("idle");
  }
}

void ViewerNode::OnMouse(const display::Window::Input& in) {
  using Mouse = display::Window::Input::Mouse;
  const cv::Rect at = layout_.preview;
  if (state_.editing() || state_.zoomed() || at.empty()) return;
  const cv::Point p(std::clamp(in.at.x, at.x, at.br().x), std::clamp(in.at.y, at.y, at.br().y));
  if (in.mouse == Mouse::kDown) {
    if (!at.contains(in.at)) return;  // Only a drag begun on the preview draws.
    drag_from_ = p;
    return;
  }
  if (drag_from_.x < 0) return;
  const cv::Rect box(drag_from_, p);
  const cv::Rect2d fraction(
      static_cast<double>(box.x - at.x) / at.width, static_cast<double>(box.y - at.y) / at.height,
      static_cast<double>(box.width) / at.width, static_cast<double>(box.height) / at.height);
  if (in.mouse != Mouse::kUp) {
    state_.Dragging(fraction);
    return;
  }
  drag_from_ = cv::Point(-1, -1);
  if (box.width < 4 || box.height < 4) {  // A click: no hint.
    state_.Dragging(cv::Rect2d());
    Do(ViewerState::Action::kClearHint);
    return;
  }
  state_.SetHint(fraction);
}

}  // namespace vellum::station
