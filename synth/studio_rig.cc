#include "synth/studio_rig.h"

namespace crease {

void StudioRigOptions::VisitFields(OptionVisitor& v) {
  v.Field("head", head);
  v.Field("ict_rig", ict_rig);
  v.Section("ict", ict);
  v.Section("procedural", procedural);
}

void StudioRigOptions::Check() const {
  ict.Check();
  procedural.Check();
}

FaceRig BuildStudioRig(const StudioRigOptions& options) {
  options.Check();
  if (options.head == StudioHead::kProcedural) return BuildProceduralRig(options.procedural);
  return BuildIctStudioRig(
      ReadRig(options.ict_rig.empty() ? VendoredIctRigPath() : std::filesystem::path(options.ict_rig)), options.ict);
}

}  // namespace crease
