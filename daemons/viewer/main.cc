// vellum-viewer: the operator's window at the gantry (daemons/viewer/viewer_node.h).
#include <filesystem>
#include <memory>
#include <stdexcept>

#include "daemons/viewer/viewer_node.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  const std::vector<Flags::Spec> own = {
      {"size", "WxH", "window size", "1280x720"},
      {"fullscreen", "BOOL", "full screen", "false"},
      {"data", "DIR",
       "the station's data folder: the operator's sequence (the next folio, a retake offered, "
       "the attempts) is kept in <DIR>/viewer-session.json and taken up again at a restart",
       "scans"},
  };
  return DaemonMain(argc, argv, "vellum-viewer",
                    "The operator's window: live camera preview, scan progress, the daemons'\n"
                    "status, and each finished scan's texture, depth, strain and restored page.\n"
                    "Keys: e = the next scan's identity (a form: Tab moves, Space chooses the\n"
                    "side, Return closes), s or Enter = start a scan (the folio then advances;\n"
                    "after a failure or a FAIL the folio is offered again first: a retake),\n"
                    "u = undo the last advance (or go on without the retake offered),\n"
                    "z = 100% zoom with a focus figure, c = the session's contact sheet,\n"
                    "drag a box over the leaf in the preview = the leaf hint every scan\n"
                    "carries (where the leaf is not at the view's centre), h = clear it,\n"
                    "left/right = step through results, q = quit (y confirms).",
                    Join(DaemonFlagSpecs(false), own), [](const Flags& flags, Node& node) {
                      display::WindowOptions window;
                      window.title = "vellum station";
                      window.size = flags.GetSize("size");
                      window.fullscreen = flags.GetBool("fullscreen");
                      RequireValid(window);
                      ViewerNodeOptions options;
                      const std::string data = flags.Get("data");
                      std::error_code ec;
                      std::filesystem::create_directories(data, ec);
                      options.session_file = data + "/viewer-session.json";
                      RequireValid(options);
                      ViewerNode viewer(&node, std::make_unique<display::Window>(window), options);
                      return node.Run([&] { viewer.Tick(); }, 20);
                    });
}
