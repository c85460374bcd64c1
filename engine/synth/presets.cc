#include "engine/synth/presets.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <random>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig::synth {
namespace {

constexpr int kMaxPoseAttempts = 20000;
constexpr int kOutlineSamplesPerEdge = 16;
constexpr double kMaxViewAngleDeg = 75.0;  // line of sight to any corner vs the board normal

double DegToRad(double deg) { return deg * M_PI / 180.0; }

std::string IndexedName(const char* prefix, int index) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%s_%03d", prefix, index);
  return buffer;
}

void CheckImageSize(int width, int height) {
  OMNIRIG_CHECK(width >= 64 && height >= 64 && width <= 8192 && height <= 8192,
                "image size must be within 64 .. 8192 pixels, got " << width << " x " << height);
}

// An upright board at `centre_in_cam` facing the camera (its +z along the line of sight, its
// -y towards the camera's -z, i.e. up for an upright sensor), then rolled in its plane and
// tilted about an in-plane axis.
std::optional<Eigen::Matrix3d> BoardRotation(const Eigen::Vector3d& centre_in_cam, double roll_rad,
                                             double tilt_rad, double tilt_axis_rad) {
  const Eigen::Vector3d z = centre_in_cam.normalized();
  Eigen::Vector3d y = Eigen::Vector3d::UnitZ() - z.z() * z;
  if (y.norm() < 1e-3) return std::nullopt;
  y.normalize();
  const Eigen::Vector3d x = y.cross(z);
  Eigen::Matrix3d rotation;
  rotation << x, y, z;
  rotation = Eigen::AngleAxisd(roll_rad, z).toRotationMatrix() * rotation;
  const Eigen::Vector3d tilt_axis =
      std::cos(tilt_axis_rad) * rotation.col(0) + std::sin(tilt_axis_rad) * rotation.col(1);
  return Eigen::AngleAxisd(tilt_rad, tilt_axis).toRotationMatrix() * rotation;
}

// Whether the whole board is seen well by `camera` from cam_from_board.
bool BoardFullyVisible(const SynthCamera& camera, const Rigid3d& cam_from_board,
                       const CheckerboardSpec& board, const BoardPoseOptions& options) {
  // The printed side faces the board's -z: the camera must sit at negative board z.
  if (!(cam_from_board.Inverse().translation.z() < 0.0)) return false;
  const Eigen::Vector3d normal_in_cam = cam_from_board.rotation * Eigen::Vector3d::UnitZ();
  const auto outline = BoardOutline(board);
  for (int edge = 0; edge < 4; ++edge) {
    for (int s = 0; s < kOutlineSamplesPerEdge; ++s) {
      const double f = static_cast<double>(s) / kOutlineSamplesPerEdge;
      const Eigen::Vector3d point = (1 - f) * outline[edge] + f * outline[(edge + 1) % 4];
      const Eigen::Vector3d point_in_cam = cam_from_board * point;
      if (!ProjectVisible(camera, point_in_cam, options.min_margin_px)) return false;
      if (point_in_cam.normalized().dot(normal_in_cam) < std::cos(DegToRad(kMaxViewAngleDeg))) {
        return false;
      }
    }
  }
  const auto corners = ProjectBoardCorners(camera, cam_from_board, board);
  for (int r = 0; r < board.rows; ++r) {
    for (int c = 0; c < board.cols; ++c) {
      const Eigen::Vector2d& p = corners[r * board.cols + c];
      if (!p.allFinite()) return false;
      if (c + 1 < board.cols &&
          (corners[r * board.cols + c + 1] - p).norm() < options.min_square_px) {
        return false;
      }
      if (r + 1 < board.rows &&
          (corners[(r + 1) * board.cols + c] - p).norm() < options.min_square_px) {
        return false;
      }
    }
  }
  return true;
}

RenderOptions ViewRenderOptions(const RenderOptions& base, uint64_t seed, int view, int camera) {
  RenderOptions options = base;
  options.seed = DeriveSeed(seed, 1000 + 2 * static_cast<uint64_t>(view) + camera);
  return options;
}

std::array<SynthCamera, 2> RigCameras(const std::optional<std::array<SynthCamera, 2>>& cameras,
                                      int width, int height) {
  std::array<SynthCamera, 2> out =
      cameras ? *cameras
              : std::array<SynthCamera, 2>{DefaultCamera(width, height),
                                           DefaultSecondCamera(width, height)};
  out[0].Check();
  out[1].Check();
  return out;
}

StereoRig MakeStereoRig(const std::array<SynthCamera, 2>& cameras, const Rigid3d& cam0_from_cam1) {
  StereoRig rig;
  rig.cam0 = cameras[0].model;
  rig.cam1 = cameras[1].model;
  rig.cam0_from_cam1 = cam0_from_cam1;
  return rig;
}

void CheckCam0FromCam1(const Rigid3d& cam0_from_cam1) {
  OMNIRIG_CHECK(cam0_from_cam1.translation.allFinite() &&
                    std::abs(cam0_from_cam1.rotation.norm() - 1.0) < 1e-6,
                "cam0_from_cam1 must be a finite rigid transform");
}

// Adds the frame and the hand of `look` around a board at world_from_board.
void AddBoardSurroundings(const CheckerboardSpec& board, const BoardLook& look,
                          const Rigid3d& world_from_board, const Eigen::Vector3d& eye_in_world,
                          Scene* scene) {
  // The side of the board the eye is on (the printed side): the frame goes behind, the hand in
  // front.
  const Eigen::Vector3d eye_in_board = world_from_board.Inverse() * eye_in_world;
  const double front = eye_in_board.z() >= 0.0 ? 1.0 : -1.0;
  const std::vector<Eigen::Vector3d> outline = BoardOutline(board);
  const Eigen::Vector3d centre = 0.5 * (outline[0] + outline[2]);
  TextureSpec plain;
  plain.style = TextureSpec::Style::kPlain;
  if (look.frame_width_m > 0.0) {
    plain.color_rgb = Eigen::Vector3d::Constant(look.frame_grey);
    const Rigid3d board_from_frame(Eigen::Quaterniond::Identity(),
                                   centre - Eigen::Vector3d(0.0, 0.0, 0.002 * front));
    scene->AddPlane(world_from_board * board_from_frame,
                    board.width_m() + 2.0 * look.frame_width_m,
                    board.height_m() + 2.0 * look.frame_width_m, plain, "frame");
  }
  if (look.hand) {
    // A palm of 7 x 9 cm, 2 cm thick, just in front of the board, reaching 2.5 cm into the board
    // from the outline's first corner along both sides: the margin and, with a narrow margin,
    // part of the outer square.
    plain.color_rgb = Eigen::Vector3d(0.85, 0.75, 0.65);
    const Eigen::Vector3d palm_centre = outline[0] + Eigen::Vector3d(-0.01, -0.02, 0.012 * front);
    scene->AddBox(world_from_board * Rigid3d(Eigen::Quaterniond::Identity(), palm_centre),
                  Eigen::Vector3d(0.07, 0.09, 0.02), plain, "hand");
  }
}

// Adds the specular highlight of `look` to a rendered view: a Gaussian spot centred on the
// board's second square of its second row, sized from the squares around it in the image.
void AddHighlight(const BoardLook& look, const CheckerboardSpec& board,
                  const std::vector<Eigen::Vector2d>& corners_px, cv::Mat* image) {
  if (look.highlight_sigma_squares <= 0.0) return;
  const int c = std::min(1, board.cols - 2), r = std::min(1, board.rows - 2);
  const Eigen::Vector2d& a = corners_px[r * board.cols + c];
  const Eigen::Vector2d& b = corners_px[(r + 1) * board.cols + c + 1];
  if (!a.allFinite() || !b.allFinite()) return;
  const Eigen::Vector2d centre = 0.5 * (a + b);
  const double sigma = look.highlight_sigma_squares * (b - a).norm() / std::sqrt(2.0);
  const int reach = static_cast<int>(std::ceil(3.0 * sigma));
  const int channels = image->channels();
  for (int v = std::max(0, static_cast<int>(centre.y()) - reach);
       v <= std::min(image->rows - 1, static_cast<int>(centre.y()) + reach); ++v) {
    uint8_t* row = image->ptr<uint8_t>(v);
    for (int u = std::max(0, static_cast<int>(centre.x()) - reach);
         u <= std::min(image->cols - 1, static_cast<int>(centre.x()) + reach); ++u) {
      const double d2 = (Eigen::Vector2d(u, v) - centre).squaredNorm();
      const double add = look.highlight_level * std::exp(-0.5 * d2 / (sigma * sigma));
      for (int k = 0; k < channels; ++k) {
        row[u * channels + k] = cv::saturate_cast<uint8_t>(row[u * channels + k] + add);
      }
    }
  }
}

}  // namespace

void BoardPoseOptions::Check() const {
  OMNIRIG_CHECK(min_distance_m > 0.0 && max_distance_m >= min_distance_m,
                "board distances must satisfy 0 < min <= max, got " << min_distance_m << " .. "
                                                                    << max_distance_m);
  OMNIRIG_CHECK_IN(max_tilt_deg, '[', 0, 80, ')');
  OMNIRIG_CHECK_IN(max_roll_deg, '[', 0, 180, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(min_margin_px);
  OMNIRIG_CHECK_NON_NEGATIVE(min_square_px);
}

std::vector<Eigen::Vector2d> ProjectBoardCorners(const SynthCamera& camera,
                                                 const Rigid3d& cam_from_board,
                                                 const CheckerboardSpec& board) {
  std::vector<Eigen::Vector2d> pixels;
  for (const Eigen::Vector3d& corner : BoardCorners(board)) {
    const auto pixel = ProjectVisible(camera, cam_from_board * corner);
    pixels.push_back(pixel ? *pixel
                           : Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN()));
  }
  return pixels;
}

Rigid3d SampleBoardPose(const std::vector<SynthCamera>& cameras,
                        const std::vector<Rigid3d>& cam_from_cam0, const CheckerboardSpec& board,
                        const BoardPoseOptions& options, int index, int num_views, uint64_t seed) {
  OMNIRIG_CHECK(!cameras.empty() && cameras.size() == cam_from_cam0.size(),
                "SampleBoardPose needs one cam_from_cam0 per camera");
  OMNIRIG_CHECK(num_views >= 1 && index >= 0 && index < num_views, "view index out of range");
  board.Check();
  options.Check();
  const AnnulusBand band = ComputeAnnulusBand(cameras[0]);
  std::mt19937_64 rng(DeriveSeed(seed, static_cast<uint64_t>(index)));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const Eigen::Vector3d board_centre((board.cols - 1) * board.square_size_m / 2,
                                     (board.rows - 1) * board.square_size_m / 2, 0.0);
  for (int attempt = 0; attempt < kMaxPoseAttempts; ++attempt) {
    // Azimuths stratified around the mirror so that the views cover every direction.
    const double azimuth = 2.0 * M_PI * (index + unit(rng)) / num_views;
    const double polar =
        band.hole_angle_rad + unit(rng) * (band.rim_angle_rad - band.hole_angle_rad);
    // Near boards are favoured (squared uniform): they carry more pixels per square.
    const double near = unit(rng);
    const double distance =
        options.min_distance_m + near * near * (options.max_distance_m - options.min_distance_m);
    const Eigen::Vector3d centre =
        distance * Eigen::Vector3d(std::sin(polar) * std::cos(azimuth),
                                   std::sin(polar) * std::sin(azimuth), std::cos(polar));
    const double roll = DegToRad(options.max_roll_deg) * (2.0 * unit(rng) - 1.0);
    const double tilt = DegToRad(options.max_tilt_deg) * unit(rng);
    const auto rotation = BoardRotation(centre, roll, tilt, 2.0 * M_PI * unit(rng));
    if (!rotation) continue;
    const Rigid3d cam0_from_board(Eigen::Quaterniond(*rotation), centre - *rotation * board_centre);
    bool visible = true;
    for (size_t k = 0; k < cameras.size() && visible; ++k) {
      visible = BoardFullyVisible(cameras[k], cam_from_cam0[k] * cam0_from_board, board, options);
    }
    if (visible) return cam0_from_board;
  }
  throw InvalidArgument(
      "no board pose keeps the whole board inside the mirror annulus; use a "
      "smaller board, a larger max distance or a smaller pixel margin");
}

Scene MakeCalibrationBackground(uint64_t seed) {
  // A room around the camera (world = camera frame, +z down): floor 1.2 m below, ceiling 1.6 m
  // above, off-centre so that the walls are at different distances.
  Scene scene;
  TextureSpec walls;
  walls.style = TextureSpec::Style::kSoft;
  walls.seed = DeriveSeed(seed, 7);
  walls.texel_size_m = 0.01;
  walls.color_rgb = Eigen::Vector3d(0.95, 0.92, 0.85);
  scene.AddBox(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.4, -0.3, -0.2)),
               Eigen::Vector3d(6.0, 5.0, 2.8), walls, "room");
  return scene;
}

void BoardLook::Check() const {
  OMNIRIG_CHECK_IN(frame_width_m, '[', 0, 1, ']');
  OMNIRIG_CHECK_IN(frame_grey, '(', 0, 1, ']');
  OMNIRIG_CHECK_IN(highlight_sigma_squares, '[', 0, 10, ']');
  OMNIRIG_CHECK_IN(highlight_level, '[', 0, 255, ']');
}

void MonoCalibrationOptions::Check() const {
  OMNIRIG_CHECK_IN(num_views, '[', 1, 10000, ']');
  CheckImageSize(width, height);
  if (camera) camera->Check();
  board.Check();
  look.Check();
  poses.Check();
  render.Check();
}

MonoCalibrationSet MakeMonoCalibrationSet(const MonoCalibrationOptions& options,
                                          const ProgressSink& progress) {
  options.Check();
  MonoCalibrationSet set;
  set.camera = options.camera ? *options.camera : DefaultCamera(options.width, options.height);
  set.board = options.board;
  if (options.textured_background) set.background = MakeCalibrationBackground(options.seed);
  Scene scene = set.background;
  const int board_index = scene.AddCheckerboard(options.board, Rigid3d());
  const Renderer renderer(set.camera, options.render.num_threads);
  for (int view = 0; view < options.num_views; ++view) {
    progress.ThrowIfCancelled();
    const Rigid3d cam_from_board =
        SampleBoardPose({set.camera}, {Rigid3d()}, options.board, options.poses, view,
                        options.num_views, options.seed);
    scene.SetBoardPose(board_index, cam_from_board);  // world frame = camera frame
    Scene view_scene = scene;
    AddBoardSurroundings(options.board, options.look, cam_from_board, Eigen::Vector3d::Zero(),
                         &view_scene);
    set.names.push_back(IndexedName("view", view));
    set.images.push_back(renderer.Render(view_scene, Rigid3d(),
                                         ViewRenderOptions(options.render, options.seed, view, 0)));
    set.cam_from_board.push_back(cam_from_board);
    set.corners_px.push_back(ProjectBoardCorners(set.camera, cam_from_board, options.board));
    AddHighlight(options.look, options.board, set.corners_px.back(), &set.images.back());
    progress.Report(static_cast<double>(view + 1) / options.num_views, "render", set.names.back());
  }
  return set;
}

Rigid3d DefaultCam0FromCam1() {
  const Eigen::Vector3d axis = Eigen::Vector3d(1.0, 0.5, 0.2).normalized();
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(DegToRad(0.3), axis)),
                 Eigen::Vector3d(0.0, 0.0, 0.1));
}

void StereoBoardOptions::Check() const {
  OMNIRIG_CHECK_IN(num_pairs, '[', 1, 10000, ']');
  CheckImageSize(width, height);
  if (cameras) {
    (*cameras)[0].Check();
    (*cameras)[1].Check();
  }
  CheckCam0FromCam1(cam0_from_cam1);
  board.Check();
  poses.Check();
  render.Check();
}

StereoBoardSet MakeStereoBoardSet(const StereoBoardOptions& options, const ProgressSink& progress) {
  options.Check();
  StereoBoardSet set;
  set.cameras = RigCameras(options.cameras, options.width, options.height);
  set.rig = MakeStereoRig(set.cameras, options.cam0_from_cam1);
  set.board = options.board;
  if (options.textured_background) set.background = MakeCalibrationBackground(options.seed);
  Scene scene = set.background;
  const int board_index = scene.AddCheckerboard(options.board, Rigid3d());
  const std::array<Renderer, 2> renderers{Renderer(set.cameras[0], options.render.num_threads),
                                          Renderer(set.cameras[1], options.render.num_threads)};
  const std::vector<Rigid3d> cam_from_cam0{Rigid3d(), options.cam0_from_cam1.Inverse()};
  for (int pair = 0; pair < options.num_pairs; ++pair) {
    progress.ThrowIfCancelled();
    const Rigid3d cam0_from_board =
        SampleBoardPose({set.cameras[0], set.cameras[1]}, cam_from_cam0, options.board,
                        options.poses, pair, options.num_pairs, options.seed);
    scene.SetBoardPose(board_index, cam0_from_board);  // world frame = cam0 frame
    set.names.push_back(IndexedName("pair", pair));
    set.cam0_from_board.push_back(cam0_from_board);
    for (int k = 0; k < 2; ++k) {
      set.images[k].push_back(renderers[k].Render(
          scene, cam_from_cam0[k], ViewRenderOptions(options.render, options.seed, pair, k)));
      set.corners_px[k].push_back(
          ProjectBoardCorners(set.cameras[k], cam_from_cam0[k] * cam0_from_board, options.board));
    }
    progress.Report(static_cast<double>(pair + 1) / options.num_pairs, "render", set.names.back());
  }
  return set;
}

void WritePng(const cv::Mat& image, const std::string& path) {
  const std::filesystem::path file(path);
  std::error_code error;
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path(), error);
  if (error || !cv::imwrite(path, image)) {
    throw std::runtime_error("cannot write image " + path);
  }
}

}  // namespace omnirig::synth
