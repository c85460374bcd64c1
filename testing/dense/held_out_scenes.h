#pragma once
// Held-out renders for dense stereo: scenes and imaging conditions unlike the room the dense
// method was developed and tuned on (engine/synth/presets.h MakeRoomScene, PNG, noise 1 grey
// level). Nothing here may be used to choose a method or an option; bench_dense reports their
// figures beside the development room's. Test and benchmark support: links engine/synth.
//
// The lounge: a 7.2 m x 5.6 m x 3.1 m room whose walls carry large, sparse shapes on coarse
// texels (12 mm, 12 shapes per m^2), one wall low-contrast (kSoft), a finely textured floor
// (3 mm texels, 250 shapes per m^2), furniture turned off the walls' axes, a panel tilted 35
// degrees and thin posts. Imaging: a low warm sun (half the light directional), vignetting 0.3,
// optical blur 0.6 px, sensor noise 2-3 grey levels, 3 x 3 supersampling, and each image saved
// as JPEG at quality 85, 90 or 95 (by frame) and decoded, as a user's camera would deliver it.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/synth/scene.h"

namespace omnirig::dense {

struct HeldOutSequence {
  std::string description;
  synth::Scene scene;  // z-up world, floor at z = 0
  StereoRig rig;       // the default rig of engine/synth/presets.h (100 mm vertical baseline)
  std::vector<Rigid3d> world_from_rig;         // the rig frame is cam0's
  std::vector<int> jpeg_quality;               // per frame
  std::array<std::vector<cv::Mat>, 2> images;  // decoded JPEGs, BGR, 1024 x 768
};

// num_frames (>= 1) poses spread around the lounge, 1.15-1.35 m above the floor, headings
// turned; deterministic in seed. `clean`: the same renders without sensor noise and without
// the JPEG (lighting, vignetting and blur as they are), to separate what the noise and the
// compression cost from what the matching itself does.
HeldOutSequence MakeHeldOutLounge(int num_frames, uint64_t seed = 11, bool clean = false);

}  // namespace omnirig::dense
