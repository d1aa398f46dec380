// A family of scenes for the virtual gantry, drawn at random from a seed: what a library brings to
// the station, not the scenes a test was tuned on. Each draw picks the leaf's shape (flat, curl,
// fold, wave, cone, ripple, a sharp crease either way up, a random smooth developable sheet, or
// an open book whose pages rise 20 to 85 degrees into the gutter), its rim height above what it
// rests on (0 to 0.5 mm), what it rests on (a table or a support of albedo 0.05 to 0.9, a paper
// frame), a burnt outline with holes, what is on the page (text, a checkerboard, nothing, colour),
// its size, place and turn, and how the camera draws it (noise, shot noise, lens blur, the
// projector's defocus, ambient light, the surround's grain): the renderer differs scene to scene
// as another renderer differs from ours.
#pragma once

#include <cstdint>
#include <string>

#include "core/common/object_kind.h"
#include "core/sim/gantry.h"
#include "core/sim/page.h"
#include "core/sim/texture.h"

namespace vellum {

struct FamilyScene {
  uint64_t seed = 0;
  std::string shape;       // flat, curl, fold, wave, cone, ripple, crease, developable, spread.
  PageOptions page;        // For a spread, each page's (the gantry makes both).
  TextureOptions texture;  // kCheckerboard where Experiment I can be measured.
  LightOptions light;      // The renderer: noise, blur, defocus, ambient, the table.
  SceneOptions scene;      // Support, frame or spread.
  ObjectKind said = ObjectKind::kAuto;  // What the operator says it is.
  // A scene at the view's edge (DrawEdgeScene): the side (0 left, 1 right, 2 top, 3 bottom, as
  // the camera sees them; -1: none) and how far inside it the page's outline lies, camera pixels
  // (negative: past it, the leaf runs off the view).
  int edge_side = -1;
  double edge_margin_px = 0;

  bool book() const { return scene.spread; }
  // One line: the seed and every choice that matters, for a table row and a failure message.
  std::string Describe() const;
};

// The scene of `seed` (the same seed gives the same scene), for the default rig's view (400 x
// 300 mm on the table): every leaf lies wholly inside it.
FamilyScene DrawFamilyScene(uint64_t seed);

// The scene of `seed` moved square to one side of the view: half run off it by 2 to 40 mm, half
// lie 2 to 15 mm inside it, for what the station says of a leaf at the edge.
FamilyScene DrawEdgeScene(uint64_t seed);

}  // namespace vellum
