#pragma once
// Two runs through the same places for the saved-map tests: circles in the synthetic room
// (engine/synth, the room of ShortSequenceOptions: 640x480, image noise 1 grey level), each
// with its own centre, radius, starting angle and lighting, the rig facing along the path.

#include <cstdint>

#include <Eigen/Core>

#include "engine/synth/presets.h"
#include "engine/synth/render.h"

namespace omnirig::slam {

struct CircleRun {
  int num_frames = 60;
  Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
  double radius_m = 1.2;
  double start_rad = 0.0;
  double laps = 1.0;
  synth::Lighting lighting;  // default: the room's own light
  std::uint64_t noise_seed = 7;
};

// The room's scene and rig, frames "frame_000".. along the circle, timestamps 0.1 s apart.
synth::StereoSequence RenderCircleRun(const CircleRun& run);

// The first run of the tests: one lap of 1.2 m radius round the room's centre in its own light.
CircleRun FirstRun();
// The second: one lap of 0.95 m radius round a centre 0.25 m away, starting a quarter turn on,
// in the dim, warm light of a low sun (synth::LapLighting(1)), other image noise.
CircleRun SecondRun();

}  // namespace omnirig::slam
