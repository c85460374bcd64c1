// The stereo sequence preset: textured scenes in a z-up world and a rig trajectory through them.

#include <cmath>
#include <cstdio>

#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

Rigid3d At(double x, double y, double z, double yaw_rad = 0.0) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(x, y, z));
}

TextureSpec Rich(uint64_t seed, uint64_t salt, const Eigen::Vector3d& rgb,
                 double shapes_per_m2 = 40.0, double texel_size_m = 0.005) {
  TextureSpec spec;
  spec.texel_size_m = texel_size_m;
  spec.style = TextureSpec::Style::kRich;
  spec.seed = DeriveSeed(seed, salt);
  spec.color_rgb = rgb;
  spec.shapes_per_m2 = shapes_per_m2;
  return spec;
}

// The rig's path: a gentle S-curve of length ~path_length_m along the world's x axis, centred
// on the origin, with the heading following the tangent and a small roll/pitch sway.
Rigid3d WorldFromRigOnPath(const StereoSequenceOptions& options, int frame) {
  const double length = options.path_length_m;
  const double s = options.num_frames > 1 ? length * frame / (options.num_frames - 1) : 0.0;
  const double amplitude = 0.4;
  const double x = s - 0.5 * length;
  const double y = amplitude * std::sin(2.0 * M_PI * s / length);
  const double dy_ds = amplitude * 2.0 * M_PI / length * std::cos(2.0 * M_PI * s / length);
  const double yaw = std::atan2(dy_ds, 1.0);
  const Rigid3d upright =
      WorldFromUprightCamera(Eigen::Vector3d(x, y, options.sensor_height_m), yaw);
  // Sway of about one degree, as on a moving platform.
  const double roll = 0.015 * std::sin(1.3 * s), pitch = 0.012 * std::sin(2.1 * s + 0.5);
  const Eigen::Quaterniond sway(Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()));
  return upright * Rigid3d(sway, Eigen::Vector3d::Zero());
}

std::string FrameName(int index) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "frame_%03d", index);
  return buffer;
}

}  // namespace

Scene MakeRoomScene(uint64_t seed) {
  Scene scene;
  scene.AddBox(At(0.0, 0.0, 1.4), Eigen::Vector3d(10.0, 7.0, 2.8),
               Rich(seed, 1, Eigen::Vector3d(0.95, 0.9, 0.8)), "room");
  scene.AddBox(At(-2.5, 2.6, 0.375, 0.1), Eigen::Vector3d(1.6, 0.9, 0.75),
               Rich(seed, 2, Eigen::Vector3d(0.8, 0.55, 0.35), 80.0), "table");
  scene.AddBox(At(2.0, -2.7, 0.45, -0.2), Eigen::Vector3d(1.2, 0.8, 0.9),
               Rich(seed, 3, Eigen::Vector3d(0.5, 0.7, 0.9), 80.0), "desk");
  scene.AddBox(At(4.6, 1.0, 0.9), Eigen::Vector3d(0.5, 1.6, 1.8),
               Rich(seed, 4, Eigen::Vector3d(0.9, 0.85, 0.5), 80.0), "cabinet");
  scene.AddBox(At(-4.6, -1.5, 0.6), Eigen::Vector3d(0.6, 1.2, 1.2),
               Rich(seed, 5, Eigen::Vector3d(0.6, 0.9, 0.6), 80.0), "shelf");
  scene.AddBox(At(0.5, 2.9, 1.0), Eigen::Vector3d(2.0, 0.4, 2.0),
               Rich(seed, 6, Eigen::Vector3d(0.9, 0.6, 0.6), 80.0), "bookcase");
  for (int i = 0; i < 4; ++i) {
    const double x = i < 2 ? -1.5 : 1.5, y = (i % 2 == 0) ? -1.7 : 1.7;
    scene.AddCylinder(At(x, y, 0.0), 0.2, 2.8,
                      Rich(seed, 10 + i, Eigen::Vector3d(0.85, 0.85, 0.9), 120.0),
                      "pillar_" + std::to_string(i));
  }
  return scene;
}

Scene MakeStreetScene(uint64_t seed) {
  Scene scene;
  scene.SetBackgroundRgb(Eigen::Vector3d(0.6, 0.72, 0.9));
  scene.AddPlane(At(0.0, 0.0, 0.0), 40.0, 14.0,
                 Rich(seed, 1, Eigen::Vector3d(0.55, 0.55, 0.58), 30.0), "ground");
  // Building fronts on both sides of the street, of varied widths and heights.
  const double widths[] = {5.0, 7.0, 4.0, 6.0, 5.5, 6.5, 4.5};
  for (int side = 0; side < 2; ++side) {
    double x = -18.0 + side * 2.0;
    for (int b = 0; x < 18.0; ++b) {
      const double width = widths[(b + 3 * side) % 7];
      const double height = 6.0 + 2.0 * ((b * 5 + side * 3) % 4);
      const double y = (side == 0 ? 1 : -1) * (6.0 + 0.3 * (b % 3));
      const Eigen::Vector3d rgb(0.7 + 0.1 * (b % 3), 0.6 + 0.1 * ((b + 1) % 3),
                                0.5 + 0.15 * (b % 2));
      scene.AddBox(At(x + 0.5 * width, y, 0.5 * height), Eigen::Vector3d(width - 0.2, 3.0, height),
                   Rich(seed, 100 + 20 * side + b, rgb, 30.0, 0.012),
                   "building_" + std::to_string(side) + "_" + std::to_string(b));
      x += width;
    }
  }
  // Poles and parked cars between the path and the fronts.
  for (int i = 0; i < 8; ++i) {
    const double x = -14.0 + 4.0 * i, y = (i % 2 == 0) ? 3.6 : -3.6;
    scene.AddCylinder(At(x, y, 0.0), 0.1, 4.0,
                      Rich(seed, 200 + i, Eigen::Vector3d(0.6, 0.6, 0.6), 200.0),
                      "pole_" + std::to_string(i));
  }
  for (int i = 0; i < 4; ++i) {
    const double x = -6.0 + 4.5 * i, y = (i % 2 == 0) ? -2.6 : 2.7;
    const Eigen::Vector3d rgb(0.3 + 0.2 * i, 0.4, 0.9 - 0.2 * i);
    scene.AddBox(At(x, y, 0.7, 0.05 * i), Eigen::Vector3d(4.0, 1.8, 1.4),
                 Rich(seed, 300 + i, rgb, 80.0), "car_" + std::to_string(i));
  }
  return scene;
}

void StereoSequenceOptions::Check() const {
  OMNIRIG_CHECK(num_frames >= 1 && num_frames <= 100000, "num_frames must be in [1, 100000]");
  OMNIRIG_CHECK(path_length_m >= 0.0 && path_length_m <= 20.0,
                "path_length_m must be in [0, 20] (the scenes are about 10 m across)");
  OMNIRIG_CHECK(frame_interval_s > 0.0, "frame_interval_s must be positive");
  OMNIRIG_CHECK(sensor_height_m > 0.2 && sensor_height_m < 2.5,
                "sensor_height_m must be in (0.2, 2.5) to stay inside the room");
  OMNIRIG_CHECK(width >= 64 && height >= 64 && width <= 8192 && height <= 8192,
                "image size must be within 64 .. 8192 pixels");
  if (cameras) {
    (*cameras)[0].Check();
    (*cameras)[1].Check();
  }
  OMNIRIG_CHECK(cam0_from_cam1.translation.allFinite(), "cam0_from_cam1 must be finite");
  render.Check();
}

StereoSequence MakeStereoSequence(const StereoSequenceOptions& options,
                                  const ProgressSink& progress) {
  options.Check();
  StereoSequence sequence;
  sequence.cameras = options.cameras ? *options.cameras
                                     : std::array<SynthCamera, 2>{
                                           DefaultCamera(options.width, options.height),
                                           DefaultSecondCamera(options.width, options.height)};
  sequence.rig.cam0 = sequence.cameras[0].model;
  sequence.rig.cam1 = sequence.cameras[1].model;
  sequence.rig.cam0_from_cam1 = options.cam0_from_cam1;
  sequence.scene = options.environment == StereoSequenceOptions::Environment::kRoom
                       ? MakeRoomScene(options.seed)
                       : MakeStreetScene(options.seed);
  const std::array<Renderer, 2> renderers{
      Renderer(sequence.cameras[0], options.render.num_threads),
      Renderer(sequence.cameras[1], options.render.num_threads)};
  const Rigid3d cam1_from_cam0 = options.cam0_from_cam1.Inverse();
  for (int frame = 0; frame < options.num_frames; ++frame) {
    progress.ThrowIfCancelled();
    const Rigid3d world_from_rig = WorldFromRigOnPath(options, frame);
    sequence.names.push_back(FrameName(frame));
    sequence.timestamps_s.push_back(frame * options.frame_interval_s);
    sequence.world_from_rig.push_back(world_from_rig);
    const Rigid3d cam0_from_world = world_from_rig.Inverse();
    const Rigid3d cam_from_world[2] = {cam0_from_world, cam1_from_cam0 * cam0_from_world};
    for (int k = 0; k < 2; ++k) {
      RenderOptions render = options.render;
      render.seed = DeriveSeed(options.seed, 5000 + 2 * static_cast<uint64_t>(frame) + k);
      sequence.images[k].push_back(renderers[k].Render(sequence.scene, cam_from_world[k], render));
    }
    progress.Report(static_cast<double>(frame + 1) / options.num_frames, "render",
                    sequence.names.back());
  }
  return sequence;
}

}  // namespace omnirig::synth
