// The studio's head rig by name: the realistic ICT-FaceKit head (synth/ict_head.h,
// the default) or the procedural head (synth/procedural_rig.h). One options struct
// for `crease synth rig` and the experiment runner's rig stage.
#pragma once

#include <array>
#include <string>

#include "core/face_rig.h"
#include "core/options.h"
#include "synth/ict_head.h"
#include "synth/procedural_rig.h"

namespace crease {

// StudioRigOptions::head (see there).
enum class StudioHead { kIct, kProcedural };
constexpr std::array<const char*, 2> OptionEnumNames(StudioHead) { return {"ict", "procedural"}; }

struct StudioRigOptions {
  StudioHead head = StudioHead::kIct;  // "ict" (ICT-FaceKit, realistic) or "procedural"
  std::string ict_rig;       // the imported ICT rig; "" = the vendored data/ict/ict_face_light.crig
  IctHeadOptions ict;               // head = ict (fields: identity_modes, eyelashes, iris_radius_mm, …)
  ProceduralRigOptions procedural;  // head = procedural (fields: face_columns, hair_thickness_mm, …)

  // Keys: head, ict_rig, and the fields of both heads' options (no two share a name).
  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Builds the rig; deterministic. Throws Error for an unknown head or a bad ICT file.
FaceRig BuildStudioRig(const StudioRigOptions& options);

}  // namespace crease
