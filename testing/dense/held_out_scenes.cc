#include "testing/dense/held_out_scenes.h"

#include <cmath>

#include <opencv2/imgcodecs.hpp>

#include "engine/synth/presets.h"
#include "engine/synth/render.h"
#include "engine/synth/synth_camera.h"
#include "engine/util/check.h"

namespace omnirig::dense {
namespace {

Rigid3d At(double x, double y, double z, double yaw_rad = 0.0) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(x, y, z));
}

synth::TextureSpec Texture(uint64_t seed, uint64_t salt, const Eigen::Vector3d& rgb,
                           double shapes_per_m2, double texel_m,
                           synth::TextureSpec::Style style = synth::TextureSpec::Style::kRich) {
  synth::TextureSpec spec = synth::RichTexture(seed, salt, rgb, shapes_per_m2, texel_m);
  spec.style = style;
  return spec;
}

synth::Scene MakeLoungeScene(uint64_t seed) {
  using synth::TextureSpec;
  synth::Scene scene;
  const double w = 7.2, d = 5.6, h = 3.1;
  // Walls as planes (each its own texture), coarse sparse shapes; one wall low-contrast.
  const Eigen::Quaterniond wall_x(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  const Eigen::Quaterniond wall_y(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()));
  scene.AddPlane(Rigid3d(wall_x, Eigen::Vector3d(w / 2, 0, h / 2)), h, d,
                 Texture(seed, 1, {0.75, 0.8, 0.7}, 12.0, 0.012), "wall_east");
  scene.AddPlane(Rigid3d(wall_x, Eigen::Vector3d(-w / 2, 0, h / 2)), h, d,
                 Texture(seed, 2, {0.85, 0.75, 0.65}, 12.0, 0.012), "wall_west");
  scene.AddPlane(Rigid3d(wall_y, Eigen::Vector3d(0, d / 2, h / 2)), w, h,
                 Texture(seed, 3, {0.7, 0.7, 0.8}, 0.0, 0.008, TextureSpec::Style::kSoft),
                 "wall_north_soft");
  scene.AddPlane(Rigid3d(wall_y, Eigen::Vector3d(0, -d / 2, h / 2)), w, h,
                 Texture(seed, 4, {0.9, 0.85, 0.8}, 18.0, 0.015), "wall_south");
  scene.AddPlane(At(0, 0, 0), w, d, Texture(seed, 5, {0.6, 0.5, 0.4}, 250.0, 0.003), "floor");
  scene.AddPlane(At(0, 0, h), w, d, Texture(seed, 6, {0.95, 0.95, 0.95}, 8.0, 0.02), "ceiling");
  // Furniture turned off the walls' axes, a tilted panel, thin posts.
  scene.AddBox(At(-2.0, 1.6, 0.4, 0.6), Eigen::Vector3d(2.2, 0.9, 0.8),
               Texture(seed, 10, {0.4, 0.5, 0.7}, 30.0, 0.01), "sofa");
  scene.AddBox(At(1.8, 1.2, 0.25, -0.45), Eigen::Vector3d(1.0, 1.0, 0.5),
               Texture(seed, 11, {0.7, 0.6, 0.3}, 150.0, 0.004), "low_table");
  scene.AddBox(At(2.6, -1.9, 1.1, 0.3), Eigen::Vector3d(0.8, 0.5, 2.2),
               Texture(seed, 12, {0.8, 0.8, 0.75}, 20.0, 0.01), "wardrobe");
  const Eigen::Quaterniond tilt(Eigen::AngleAxisd(-0.9, Eigen::Vector3d::UnitZ()) *
                                Eigen::AngleAxisd(35.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()));
  scene.AddPlane(Rigid3d(tilt, Eigen::Vector3d(-1.4, -1.5, 1.0)), 1.4, 1.2,
                 Texture(seed, 13, {0.9, 0.7, 0.7}, 60.0, 0.006), "tilted_panel");
  for (int i = 0; i < 3; ++i) {
    scene.AddCylinder(At(-0.8 + 1.3 * i, 0.9 - 1.1 * i, 0.0), 0.06, h,
                      Texture(seed, 20 + i, {0.7, 0.7, 0.7}, 300.0, 0.003),
                      "post_" + std::to_string(i));
  }
  scene.AddCylinder(At(0.3, 2.1, 0.0), 0.35, 0.7, Texture(seed, 30, {0.5, 0.7, 0.5}, 40.0, 0.008),
                    "planter");
  return scene;
}

}  // namespace

HeldOutSequence MakeHeldOutLounge(int num_frames, uint64_t seed, bool clean) {
  OMNIRIG_CHECK(num_frames >= 1, "num_frames must be at least 1, got " << num_frames);
  HeldOutSequence sequence;
  sequence.description =
      clean ? "held-out lounge, clean (no sensor noise, no JPEG; vignetting 0.3, blur 0.6 px, "
              "low warm sun)"
            : "held-out lounge (other textures and scales, JPEG 85-95, noise 2-3, vignetting "
              "0.3, blur 0.6 px, low warm sun)";
  sequence.scene = MakeLoungeScene(seed);
  const std::array<synth::SynthCamera, 2> cameras{synth::DefaultCamera(1024, 768),
                                                  synth::DefaultSecondCamera(1024, 768)};
  sequence.rig.cam0 = cameras[0].model;
  sequence.rig.cam1 = cameras[1].model;
  sequence.rig.cam0_from_cam1 = synth::DefaultCam0FromCam1();
  const Rigid3d cam1_from_cam0 = sequence.rig.cam0_from_cam1.Inverse();
  synth::RenderOptions render;
  render.supersampling = 3;
  render.blur_sigma_px = 0.6;
  render.vignetting = 0.3;
  render.lighting.gain = 0.9;
  render.lighting.tint_rgb = Eigen::Vector3d(1.0, 0.9, 0.75);
  render.lighting.sun_in_world = Eigen::Vector3d(0.8, -0.3, 0.35).normalized();
  render.lighting.sun_share = 0.5;
  const int qualities[] = {90, 85, 95};
  for (int f = 0; f < num_frames; ++f) {
    // Positions on an ellipse around the room's middle, headings turned by frame.
    const double a = 2.0 * M_PI * (f + 0.3) / std::max(num_frames, 3);
    const Eigen::Vector3d position(1.3 * std::cos(a), 0.9 * std::sin(a), 1.15 + 0.1 * (f % 3));
    sequence.world_from_rig.push_back(synth::WorldFromUprightCamera(position, 0.7 * f + 0.2));
    sequence.jpeg_quality.push_back(qualities[f % 3]);
    const Rigid3d cam_from_world[2] = {sequence.world_from_rig.back().Inverse(),
                                       cam1_from_cam0 * sequence.world_from_rig.back().Inverse()};
    for (int k = 0; k < 2; ++k) {
      render.noise_sigma = clean ? 0.0 : 2.0 + 0.5 * ((f + k) % 3);
      render.seed = synth::DeriveSeed(seed, 100 + 2 * static_cast<uint64_t>(f) + k);
      const cv::Mat rendered = synth::Render(sequence.scene, cameras[k], cam_from_world[k], render);
      if (clean) {
        sequence.images[k].push_back(rendered);
        continue;
      }
      std::vector<uchar> jpeg;
      cv::imencode(".jpg", rendered, jpeg, {cv::IMWRITE_JPEG_QUALITY, qualities[f % 3]});
      sequence.images[k].push_back(cv::imdecode(jpeg, cv::IMREAD_COLOR));
    }
  }
  return sequence;
}

}  // namespace omnirig::dense
