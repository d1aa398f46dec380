// vellum manifest: writes or checks a folder's SHA-256 manifest (io/manifest.h).
#include <cstdio>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "io/manifest.h"

namespace vellum {

int RunManifest(const std::vector<std::string>& args) {
  Flags flags("vellum manifest write|check DIR",
              "write: writes DIR/manifest-sha256.txt, the SHA-256 of every file under DIR\n"
              "(BagIt's format, which sha256sum -c reads: '<hash>  <path>' per line).\n"
              "check: verifies the files against it. The station writes one into each scan's\n"
              "folder (over raw/ and results/) when the scan is restored. Exit status of check:\n"
              "0 whole and unchanged; 1 a file missing, changed or not listed (each named), or\n"
              "no manifest.",
              {});
  std::vector<std::string> positional, rest;
  SplitPositional(args, &positional, &rest);
  if (!flags.Parse(rest)) return 0;
  if (positional.size() != 2 || (positional[0] != "write" && positional[0] != "check")) {
    throw UsageError("expected write DIR or check DIR (see vellum manifest --help)");
  }
  const std::string& dir = positional[1];
  if (positional[0] == "check") {
    std::vector<std::string> problems;
    const Status s = CheckManifest(dir, &problems);
    if (!s.ok()) {
      std::fprintf(stderr, "vellum manifest: %s\n", s.message().c_str());
      return 1;
    }
    for (const std::string& p : problems) std::fprintf(stderr, "vellum manifest: %s\n", p.c_str());
    if (!problems.empty()) return 1;
    std::printf("%s: every file whole and unchanged\n", dir.c_str());
    return 0;
  }
  int files = 0;
  const Status s = WriteManifest(dir, {}, &files);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum manifest: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("%d file(s) -> %s/%s\n", files, dir.c_str(), kManifestName);
  return 0;
}

}  // namespace vellum
