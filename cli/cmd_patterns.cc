#include <cstdio>

#include "cli/commands.h"
#include "core/patterns/patterns.h"
#include "flags/flags.h"
#include "flags/options.h"
#include "io/scan_io.h"

namespace vellum {

// The pattern flags shared by `patterns` and `render`.
int RunPatterns(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = {
      {"projector", "WIDTHxHEIGHT", "projector image size, any size", "1024x768"},
      {"out", "DIR", "output directory", ""},
  };
  for (const auto& s : PatternFlagSpecs()) specs.push_back(s);
  Flags flags("vellum patterns",
              "Writes the projector images of one scan (pattern_000.png, ... in projection order)\n"
              "and the matching scan.yaml. Show pattern k, capture frame_k.png.",
              specs);
  if (!flags.Parse(args)) return 0;
  const std::string out = flags.Require("out");
  const PatternSequence seq =
      MakePatternSequence(PatternOptionsFromFlags(flags, flags.GetSize("projector")));
  const Status s = WritePatterns(out, seq);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum patterns: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("wrote %zu patterns for a %dx%d projector to %s\n", seq.patterns.size(),
              seq.projector_size.width, seq.projector_size.height, out.c_str());
  return 0;
}

}  // namespace vellum
