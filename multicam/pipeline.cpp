#include "multicam/pipeline.h"

namespace previz::multicam {

void RigPipelineOptions::validate() const {
  calib.validate();
  sync.validate();
}

RigPipelineResult solveRigTake(const RigObservations& obs, const Rig& initial, const RigPipelineOptions& options) {
  options.validate();
  RigPipelineResult out;
  out.calib = calibrateRig(obs, initial, options.calib);
  // The sync check needs every camera's intrinsics and pose: the solved rig's.
  out.sync = checkSync(obs, out.calib.rig, options.sync);
  return out;
}

}  // namespace previz::multicam
