#include "testing/slam/revisit.h"

#include <cmath>
#include <cstdio>

#include "engine/synth/scene.h"
#include "engine/synth/synth_camera.h"
#include "testing/slam/sequence_accuracy.h"

namespace omnirig::slam {

synth::StereoSequence RenderCircleRun(const CircleRun& run) {
  const synth::StereoSequenceOptions options = ShortSequenceOptions(1);
  synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  for (int c = 0; c < 2; ++c) sequence.images[c].clear();
  sequence.names.clear();
  sequence.timestamps_s.clear();
  sequence.world_from_rig.clear();
  sequence.laps.clear();
  const synth::Renderer renderers[2] = {synth::Renderer(sequence.cameras[0]),
                                        synth::Renderer(sequence.cameras[1])};
  const Rigid3d cam1_from_cam0 = sequence.rig.cam0_from_cam1.Inverse();
  for (int i = 0; i < run.num_frames; ++i) {
    const double angle = run.start_rad + 2.0 * M_PI * run.laps * i / run.num_frames;
    const Eigen::Vector3d position(run.centre_m.x() + run.radius_m * std::cos(angle),
                                   run.centre_m.y() + run.radius_m * std::sin(angle),
                                   options.sensor_height_m);
    const Rigid3d world_from_rig = synth::WorldFromUprightCamera(position, angle + 0.5 * M_PI);
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%03d", i);
    sequence.names.push_back(name);
    sequence.timestamps_s.push_back(0.1 * i);
    sequence.world_from_rig.push_back(world_from_rig);
    sequence.laps.push_back(0);
    const Rigid3d cam_from_world[2] = {world_from_rig.Inverse(),
                                       cam1_from_cam0 * world_from_rig.Inverse()};
    for (int c = 0; c < 2; ++c) {
      synth::RenderOptions render = options.render;
      render.lighting = run.lighting;
      render.seed = synth::DeriveSeed(run.noise_seed, 2 * static_cast<uint64_t>(i) + c);
      sequence.images[c].push_back(renderers[c].Render(sequence.scene, cam_from_world[c], render));
    }
  }
  return sequence;
}

CircleRun FirstRun() { return CircleRun(); }

CircleRun SecondRun() {
  CircleRun run;
  run.centre_m = Eigen::Vector2d(0.2, -0.15);
  run.radius_m = 0.95;
  run.start_rad = 0.5 * M_PI;
  run.lighting = synth::LapLighting(1);
  run.noise_seed = 11;
  return run;
}

}  // namespace omnirig::slam
