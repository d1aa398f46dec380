// The processing options as flags, one group per stage, shared by `vellum process` and the
// station's daemons (vellum-decoder takes the decode group, and so on), so that both run the
// same stages with the same defaults and give the same results.
#pragma once

#include <string>
#include <vector>

#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/patterns/patterns.h"
#include "core/restore/restore.h"
#include "core/sim/gantry.h"
#include "flags/flags.h"
#include "pipeline/stages.h"

namespace vellum {

// Pattern sequence flags (--phase-steps, --period), shared by `patterns`, `render` and the
// projector daemon.
std::vector<Flags::Spec> PatternFlagSpecs();
PatternOptions PatternOptionsFromFlags(const Flags& flags, cv::Size projector);

// The virtual gantry's page, scene and camera flags (--page, --texture, --page-size, --scene,
// --outline, --thickness, --noise, --seed, ...), shared by `vellum render` and the sim camera;
// `prefix` starts each help line ("sim: ").
std::vector<Flags::Spec> SimFlagSpecs(const std::string& prefix = "");
// Fills the page, its texture (an image texture is read from disk), the scene around it, the
// camera noise and the seed (also the texture's). A bad name throws UsageError; an unreadable
// image is an error.
Status SimOptionsFromFlags(const Flags& flags, PageOptions* page, TextureOptions* texture,
                           LightOptions* light, SceneOptions* scene, uint64_t* seed);

std::vector<Flags::Spec> DecodeFlagSpecs();       // --decoder, --smooth-radius
std::vector<Flags::Spec> TriangulateFlagSpecs();  // --max-epipolar
// The flattener's: --grid, --max-warp-error, --solver, --leaf-hint.
std::vector<Flags::Spec> FlattenFlagSpecs();
// The restorer's: --view, --dpi, --deskew, --crop, --margin, --leaf-size.
std::vector<Flags::Spec> RestoreFlagSpecs();

// Each throws UsageError naming the flag when a value is bad.
DecodeOptions DecodeOptionsFromFlags(const Flags& flags);
TriangulateOptions TriangulateOptionsFromFlags(const Flags& flags);
FlattenOptions FlattenOptionsFromFlags(const Flags& flags);
// The outline, sheet and flattening options of FlattenFlagSpecs().
void FlattenGroupFromFlags(const Flags& flags, PipelineOptions* options);
// The restoration options, the expected leaf size, the camera's ICC profile and the flat and
// studio fields (read and checked) of RestoreFlagSpecs().
void RestoreGroupFromFlags(const Flags& flags, PipelineOptions* options);

// The flags of every stage (`vellum process`), and the options they give.
std::vector<Flags::Spec> PipelineFlagSpecs();
PipelineOptions PipelineOptionsFromFlags(const Flags& flags);

// Appends b to a.
// Lamps given as "X,Y,Z;X,Y,Z;..." (world mm, z > 0) for `flag`; a bad one is a UsageError
// naming the flag.
std::vector<cv::Vec3d> ParseLamps(const std::string& flag, const std::string& text);

std::vector<Flags::Spec> Join(std::vector<Flags::Spec> a, const std::vector<Flags::Spec>& b);

}  // namespace vellum
