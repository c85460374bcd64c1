// Kalibr's YAML files a user uploads to a dataset and a job names: a target (the board,
// engine/calib/board.h BoardFromKalibrTarget) when the first byte is even, a camchain (the rig's
// cameras, engine/calib/model_io.h FromKalibrCamchain) when it is odd. Each either gives a valid
// board or rig or throws InvalidArgument naming what is wrong; any other exception or a crash is
// a failure here.

#include <cstddef>
#include <cstdint>
#include <string>

#include "engine/calib/board.h"
#include "engine/calib/model_io.h"
#include "engine/util/check.h"
#include "fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace omnirig;
  if (size < 1) return 0;
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    if (data[0] % 2 == 0) {
      const BoardSpec board = BoardFromKalibrTarget(text);
      board.Check();  // throws InvalidArgument, which would be a broken promise here
      FUZZ_CHECK(board.NumCorners() >= 4);
    } else {
      const StereoRig rig = FromKalibrCamchain(text);
      rig.cam0.intrinsics.Check();
      rig.cam1.intrinsics.Check();
      FUZZ_CHECK(rig.cam0_from_cam1.translation.allFinite());
    }
  } catch (const InvalidArgument&) {
  }
  return 0;
}
