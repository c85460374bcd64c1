// The stereo sequence preset: textured scenes in a z-up world and a rig trajectory through them.

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "engine/synth/city_block.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig::synth {
namespace {

Rigid3d At(double x, double y, double z, double yaw_rad = 0.0) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(x, y, z));
}

// Sway of about one degree at distance s along the path, as on a moving platform.
Rigid3d Sway(double s) {
  const double roll = 0.015 * std::sin(1.3 * s), pitch = 0.012 * std::sin(2.1 * s + 0.5);
  const Eigen::Quaterniond sway(Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()));
  return Rigid3d(sway, Eigen::Vector3d::Zero());
}

// The S-curve path of the room and the street: length ~path_length_m along the world's x axis,
// centred on the origin, with the heading following the tangent and a small roll/pitch sway.
// `frame` may be fractional (poses within an exposure).
Rigid3d WorldFromRigOnCurve(const StereoSequenceOptions& options, double frame) {
  const double length = options.path_length_m;
  const double s = options.num_frames > 1 ? length * frame / (options.num_frames - 1) : 0.0;
  const double amplitude = 0.4;
  const double x = s - 0.5 * length;
  const double y = amplitude * std::sin(2.0 * M_PI * s / length);
  const double dy_ds = amplitude * 2.0 * M_PI / length * std::cos(2.0 * M_PI * s / length);
  const double yaw = std::atan2(dy_ds, 1.0);
  const Rigid3d upright =
      WorldFromUprightCamera(Eigen::Vector3d(x, y, options.sensor_height_m), yaw);
  return upright * Sway(s);
}

// Distance driven at `frame` on the city block's laps.
double LoopDistance(const StereoSequenceOptions& options, double frame) {
  return options.num_laps * options.path_length_m * frame / options.num_frames;
}

// The line driven around the block: the loop's centreline moved sideways by up to 0.5 m, with a
// period that is not a fraction of the lap so that each lap keeps to another line.
Eigen::Vector2d LoopLine(const CityBlockLoop& loop, double s) {
  Eigen::Vector2d point, outward;
  loop.At(s, &point, &outward);
  const double lateral_m = 0.5 * std::sin(2.0 * M_PI * s / (1.37 * loop.length_m()) + 0.3);
  return point + lateral_m * outward;
}

Rigid3d WorldFromRigOnLoop(const StereoSequenceOptions& options, const CityBlockLoop& loop,
                           double frame) {
  const double s = LoopDistance(options, frame);
  const Eigen::Vector2d point = LoopLine(loop, s);
  const Eigen::Vector2d tangent = LoopLine(loop, s + 0.01) - LoopLine(loop, s - 0.01);
  const Rigid3d upright = WorldFromUprightCamera(
      Eigen::Vector3d(point.x(), point.y(), options.sensor_height_m),
      std::atan2(tangent.y(), tangent.x()));
  return upright * Sway(s);
}

Rigid3d WorldFromRigAt(const StereoSequenceOptions& options,
                       const std::optional<CityBlockLoop>& loop, double frame) {
  return loop ? WorldFromRigOnLoop(options, *loop, frame) : WorldFromRigOnCurve(options, frame);
}

int LapAt(const StereoSequenceOptions& options, int frame) {
  if (options.environment != StereoSequenceOptions::Environment::kCityBlock) return 0;
  const int lap = static_cast<int>(LoopDistance(options, frame) / options.path_length_m);
  return std::clamp(lap, 0, options.num_laps - 1);
}

// The lighting at `frame`: LapLighting of its lap, blended from the previous lap's over the
// first 5 % of the lap.
Lighting LightingAt(const StereoSequenceOptions& options, int frame) {
  if (!options.lighting_change) return Lighting();
  const int lap = LapAt(options, frame);
  const double into_lap = LoopDistance(options, frame) / options.path_length_m - lap;
  const double w = lap == 0 ? 1.0 : std::clamp(into_lap / 0.05, 0.0, 1.0);
  if (w >= 1.0) return LapLighting(lap);
  const Lighting from = LapLighting(lap - 1), to = LapLighting(lap);
  Lighting mixed;
  mixed.gain = (1 - w) * from.gain + w * to.gain;
  mixed.tint_rgb = (1 - w) * from.tint_rgb + w * to.tint_rgb;
  mixed.sun_share = (1 - w) * from.sun_share + w * to.sun_share;
  // A light without a directional part has no meaningful direction: take the other's.
  const Eigen::Vector3d from_sun = from.sun_share > 0 ? from.sun_in_world.normalized()
                                                      : to.sun_in_world.normalized();
  const Eigen::Vector3d to_sun = to.sun_share > 0 ? to.sun_in_world.normalized() : from_sun;
  mixed.sun_in_world = ((1 - w) * from_sun + w * to_sun).normalized();
  return mixed;
}

// The poses of one image's exposure (just the frame's own without motion blur).
std::vector<Rigid3d> CamFromWorldDuringExposure(const StereoSequenceOptions& options,
                                                const std::optional<CityBlockLoop>& loop,
                                                int frame, const Rigid3d& cam_from_rig) {
  if (options.motion_blur_exposure_s <= 0.0) {
    return {cam_from_rig * WorldFromRigAt(options, loop, frame).Inverse()};
  }
  std::vector<Rigid3d> poses;
  const int n = options.motion_blur_samples;
  const double exposure_frames = options.motion_blur_exposure_s / options.frame_interval_s;
  for (int k = 0; k < n; ++k) {
    const double offset = n > 1 ? (static_cast<double>(k) / (n - 1) - 0.5) : 0.0;
    const double at = frame + offset * exposure_frames;
    poses.push_back(cam_from_rig * WorldFromRigAt(options, loop, at).Inverse());
  }
  return poses;
}

std::string FrameName(int index, int num_frames) {
  const size_t digits = std::max<size_t>(3, std::to_string(num_frames - 1).size());
  const std::string number = std::to_string(index);
  return "frame_" + std::string(digits - std::min(digits, number.size()), '0') + number;
}

}  // namespace

Scene MakeRoomScene(uint64_t seed) {
  Scene scene;
  scene.AddBox(At(0.0, 0.0, 1.4), Eigen::Vector3d(10.0, 7.0, 2.8),
               RichTexture(seed, 1, Eigen::Vector3d(0.95, 0.9, 0.8)), "room");
  scene.AddBox(At(-2.5, 2.6, 0.375, 0.1), Eigen::Vector3d(1.6, 0.9, 0.75),
               RichTexture(seed, 2, Eigen::Vector3d(0.8, 0.55, 0.35), 80.0), "table");
  scene.AddBox(At(2.0, -2.7, 0.45, -0.2), Eigen::Vector3d(1.2, 0.8, 0.9),
               RichTexture(seed, 3, Eigen::Vector3d(0.5, 0.7, 0.9), 80.0), "desk");
  scene.AddBox(At(4.6, 1.0, 0.9), Eigen::Vector3d(0.5, 1.6, 1.8),
               RichTexture(seed, 4, Eigen::Vector3d(0.9, 0.85, 0.5), 80.0), "cabinet");
  scene.AddBox(At(-4.6, -1.5, 0.6), Eigen::Vector3d(0.6, 1.2, 1.2),
               RichTexture(seed, 5, Eigen::Vector3d(0.6, 0.9, 0.6), 80.0), "shelf");
  scene.AddBox(At(0.5, 2.9, 1.0), Eigen::Vector3d(2.0, 0.4, 2.0),
               RichTexture(seed, 6, Eigen::Vector3d(0.9, 0.6, 0.6), 80.0), "bookcase");
  for (int i = 0; i < 4; ++i) {
    const double x = i < 2 ? -1.5 : 1.5, y = (i % 2 == 0) ? -1.7 : 1.7;
    scene.AddCylinder(At(x, y, 0.0), 0.2, 2.8,
                      RichTexture(seed, 10 + i, Eigen::Vector3d(0.85, 0.85, 0.9), 120.0),
                      "pillar_" + std::to_string(i));
  }
  return scene;
}

Scene MakeStreetScene(uint64_t seed) {
  Scene scene;
  scene.SetBackgroundRgb(Eigen::Vector3d(0.6, 0.72, 0.9));
  scene.AddPlane(At(0.0, 0.0, 0.0), 40.0, 14.0,
                 RichTexture(seed, 1, Eigen::Vector3d(0.55, 0.55, 0.58), 30.0), "ground");
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
                   RichTexture(seed, 100 + 20 * side + b, rgb, 30.0, 0.012),
                   "building_" + std::to_string(side) + "_" + std::to_string(b));
      x += width;
    }
  }
  // Poles and parked cars between the path and the fronts.
  for (int i = 0; i < 8; ++i) {
    const double x = -14.0 + 4.0 * i, y = (i % 2 == 0) ? 3.6 : -3.6;
    scene.AddCylinder(At(x, y, 0.0), 0.1, 4.0,
                      RichTexture(seed, 200 + i, Eigen::Vector3d(0.6, 0.6, 0.6), 200.0),
                      "pole_" + std::to_string(i));
  }
  for (int i = 0; i < 4; ++i) {
    const double x = -6.0 + 4.5 * i, y = (i % 2 == 0) ? -2.6 : 2.7;
    const Eigen::Vector3d rgb(0.3 + 0.2 * i, 0.4, 0.9 - 0.2 * i);
    scene.AddBox(At(x, y, 0.7, 0.05 * i), Eigen::Vector3d(4.0, 1.8, 1.4),
                 RichTexture(seed, 300 + i, rgb, 80.0), "car_" + std::to_string(i));
  }
  return scene;
}

Lighting LapLighting(int lap) {
  OMNIRIG_CHECK(lap >= 0, "a lap index is not negative");
  auto sun = [](double azimuth_deg, double elevation_deg) {
    const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
    return Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                           std::sin(el));
  };
  Lighting lighting;
  if (lap == 0) return lighting;
  switch ((lap - 1) % 3) {
    case 0:  // evening: dim and warm, a low sun casting strong differences between faces
      lighting.gain = 0.7;
      lighting.tint_rgb = Eigen::Vector3d(1.0, 0.88, 0.72);
      lighting.sun_in_world = sun(200.0, 15.0);
      lighting.sun_share = 0.5;
      break;
    case 1:  // noon: bright and cool, a high sun
      lighting.gain = 1.1;
      lighting.tint_rgb = Eigen::Vector3d(0.9, 0.97, 1.05);
      lighting.sun_in_world = sun(60.0, 60.0);
      lighting.sun_share = 0.3;
      break;
    default:  // overcast: grey and flat
      lighting.gain = 0.85;
      lighting.tint_rgb = Eigen::Vector3d(0.92, 0.95, 1.0);
      break;
  }
  return lighting;
}

void StereoSequenceOptions::Check() const {
  OMNIRIG_CHECK_IN(num_frames, '[', 1, 100000, ']');
  if (environment == Environment::kCityBlock) {
    // One lap around the city block.
    OMNIRIG_CHECK_IN(path_length_m, '[', CityBlockLoop::kMinLengthM, CityBlockLoop::kMaxLengthM,
                     ']');
    OMNIRIG_CHECK_IN(num_laps, '[', 1, 100, ']');
  } else {
    OMNIRIG_CHECK_IN(path_length_m, '[', 0, 20, ']');  // the scenes are about 10 m across
    OMNIRIG_CHECK(num_laps == 1, "num_laps applies to the city block's loop only");
  }
  OMNIRIG_CHECK_POSITIVE(frame_interval_s);
  OMNIRIG_CHECK_NON_NEGATIVE(motion_blur_exposure_s);
  OMNIRIG_CHECK_IN(motion_blur_samples, '[', 1, 64, ']');
  OMNIRIG_CHECK_IN(sensor_height_m, '(', 0.2, 2.5, ')');  // to stay inside the room
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
  std::array<std::vector<cv::Mat>, 2> images;
  StereoSequence sequence = RenderStereoSequence(
      options,
      [&images](int, const std::string&, const cv::Mat& cam0_image, const cv::Mat& cam1_image) {
        images[0].push_back(cam0_image);
        images[1].push_back(cam1_image);
      },
      progress);
  sequence.images = std::move(images);
  return sequence;
}

StereoSequence RenderStereoSequence(const StereoSequenceOptions& options,
                                    const StereoFrameSink& sink, const ProgressSink& progress) {
  options.Check();
  StereoSequence sequence;
  sequence.options = options;
  sequence.cameras = options.cameras ? *options.cameras
                                     : std::array<SynthCamera, 2>{
                                           DefaultCamera(options.width, options.height),
                                           DefaultSecondCamera(options.width, options.height)};
  sequence.rig.cam0 = sequence.cameras[0].model;
  sequence.rig.cam1 = sequence.cameras[1].model;
  sequence.rig.cam0_from_cam1 = options.cam0_from_cam1;
  std::optional<CityBlockLoop> loop;
  switch (options.environment) {
    case StereoSequenceOptions::Environment::kRoom:
      sequence.scene = MakeRoomScene(options.seed);
      break;
    case StereoSequenceOptions::Environment::kStreet:
      sequence.scene = MakeStreetScene(options.seed);
      break;
    case StereoSequenceOptions::Environment::kCityBlock:
      loop.emplace(options.path_length_m);
      sequence.scene = MakeCityBlockScene(*loop, options.seed);
      break;
  }
  const std::array<Renderer, 2> renderers{
      Renderer(sequence.cameras[0], options.render.num_threads),
      Renderer(sequence.cameras[1], options.render.num_threads)};
  const Rigid3d cam1_from_cam0 = options.cam0_from_cam1.Inverse();
  for (int frame = 0; frame < options.num_frames; ++frame) {
    progress.ThrowIfCancelled();
    sequence.names.push_back(FrameName(frame, options.num_frames));
    sequence.timestamps_s.push_back(frame * options.frame_interval_s);
    sequence.world_from_rig.push_back(WorldFromRigAt(options, loop, frame));
    sequence.laps.push_back(LapAt(options, frame));
    const Rigid3d cam_from_rig[2] = {Rigid3d(), cam1_from_cam0};
    cv::Mat images[2];
    for (int k = 0; k < 2; ++k) {
      RenderOptions render = options.render;
      render.seed = DeriveSeed(options.seed, 5000 + 2 * static_cast<uint64_t>(frame) + k);
      render.lighting = LightingAt(options, frame);
      images[k] = renderers[k].Render(
          sequence.scene, CamFromWorldDuringExposure(options, loop, frame, cam_from_rig[k]),
          render);
    }
    sink(frame, sequence.names.back(), images[0], images[1]);
    progress.Report(static_cast<double>(frame + 1) / options.num_frames, "render",
                    sequence.names.back());
  }
  return sequence;
}

}  // namespace omnirig::synth
