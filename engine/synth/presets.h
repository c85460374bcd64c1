#pragma once
// Ready-made synthetic data sets with ground truth, in memory. api/synth_json.h writes them to a
// folder (PNG images + ground_truth.json); `omnirig synth` is the command line.
//
//   MakeMonoCalibrationSet   one camera, a board waved around it (world frame = camera frame)
//   MakeStereoBoardSet       a vertical stereo rig, boards seen by both cameras
//                            (world frame = cam0 frame)
//   MakeStereoSequence       the rig moving through a textured room or along a street front,
//                            or driving laps around a city block (closed loops with revisits)
//
// Board views imitate a person waving a board around a catadioptric sensor: azimuths spread all
// around the mirror, distances 0.35-1.2 m, tilts up to 50 degrees, the board roughly upright;
// every view keeps the whole board (margin included) inside the mirror annulus of every camera,
// clear of the rim and hole by min_margin_px, with squares at least min_square_px wide.

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/synth/render.h"
#include "engine/synth/scene.h"
#include "engine/synth/synth_camera.h"
#include "engine/util/progress.h"

namespace omnirig::synth {

// How board views are drawn (shared by the mono and stereo board sets).
struct BoardPoseOptions {
  double min_distance_m = 0.35;  // camera centre to board centre
  double max_distance_m = 1.2;
  double max_tilt_deg = 50.0;  // angle between the board normal and the line of sight
  double max_roll_deg = 30.0;  // in-plane turn away from upright
  double min_margin_px = 8.0;  // of the board outline from the rim and the hole
  double min_square_px = 6.0;  // shortest distance between neighbouring corners in the image

  void Check() const;
};

// Draws cam_from_board for view `index` of `num_views` (azimuths stratified around the mirror)
// such that the board is fully visible in every camera of `cam_from_cam0` (cam0 itself first,
// as identity). Deterministic in (seed, index). Throws InvalidArgument when no pose fits after
// many attempts (a board too big for the mirror).
Rigid3d SampleBoardPose(const std::vector<SynthCamera>& cameras,
                        const std::vector<Rigid3d>& cam_from_cam0, const CheckerboardSpec& board,
                        const BoardPoseOptions& options, int index, int num_views, uint64_t seed);

// Exact pixel projections of the board's inner corners (BoardCorners order); NaN for a corner
// that does not project into the annulus.
std::vector<Eigen::Vector2d> ProjectBoardCorners(const SynthCamera& camera,
                                                 const Rigid3d& cam_from_board,
                                                 const CheckerboardSpec& board);

// A room around the origin with low-contrast (kSoft) walls, used behind calibration boards.
Scene MakeCalibrationBackground(uint64_t seed);

// How a board looks beyond its printed squares, as real boards do: the margin width is
// CheckerboardSpec::margin_m; these add what is held around and over it.
struct BoardLook {
  // A frame or holder around the board's outline, of another grey, frame_width_m wide (0:
  // none) and a hair behind the board; frame_grey in (0, 1] of the plain texture's level (160).
  double frame_width_m = 0.0;
  double frame_grey = 0.6;
  // A hand-like blob (a box of skin grey, in front of the board) over the board's outer corner
  // at its first corner's side: it covers the margin there and part of the outer square, no
  // inner corner.
  bool hand = false;
  // A specular highlight: a bright Gaussian spot on the board of this standard deviation in
  // squares (0: none), highlight_level grey levels at its peak (added, saturating at 255).
  double highlight_sigma_squares = 0.0;
  double highlight_level = 120.0;

  void Check() const;
};

struct MonoCalibrationOptions {
  int num_views = 20;
  int width = 1024;
  int height = 768;
  std::optional<SynthCamera> camera;  // default: DefaultCamera(width, height)
  CheckerboardSpec board;
  BoardPoseOptions poses;
  bool textured_background = true;  // a soft-textured room; otherwise plain background
  BoardLook look;
  RenderOptions render;             // noise, blur, supersampling, threads (render.seed is
                                    // replaced per view by a value derived from seed)
  uint64_t seed = 0;

  void Check() const;
};

struct MonoCalibrationSet {
  SynthCamera camera;
  CheckerboardSpec board;
  Scene background;                // the scene without the board (camera frame = world)
  std::vector<std::string> names;  // "view_000", ...
  std::vector<cv::Mat> images;
  std::vector<Rigid3d> cam_from_board;
  std::vector<std::vector<Eigen::Vector2d>> corners_px;  // per view, all corners, exact
};

MonoCalibrationSet MakeMonoCalibrationSet(const MonoCalibrationOptions& options,
                                          const ProgressSink& progress = ProgressSink());

// The default rig: cam0 = DefaultCamera, cam1 = DefaultSecondCamera, mounted vertically with
// cam1 100 mm along cam0's +z axis (below cam0 when upright: cam0 is the upper sensor), turned by
// a small misalignment of 0.3 degrees about an oblique axis as in a real mount.
Rigid3d DefaultCam0FromCam1();

struct StereoBoardOptions {
  int num_pairs = 20;
  int width = 1024;
  int height = 768;
  std::optional<std::array<SynthCamera, 2>> cameras;  // default: DefaultCamera, DefaultSecondCamera
  Rigid3d cam0_from_cam1 = DefaultCam0FromCam1();
  CheckerboardSpec board;
  BoardPoseOptions poses;
  bool textured_background = true;
  RenderOptions render;
  uint64_t seed = 0;

  void Check() const;
};

struct StereoBoardSet {
  StereoRig rig;                       // rig.cam0/cam1 == cameras[0/1].model
  std::array<SynthCamera, 2> cameras;  // with the mirror radii
  CheckerboardSpec board;
  Scene background;                // world frame = cam0 frame
  std::vector<std::string> names;  // "pair_000", ...; images[0][i] and images[1][i]
  std::array<std::vector<cv::Mat>, 2> images;
  std::vector<Rigid3d> cam0_from_board;  // cam1_from_board = rig.cam0_from_cam1.Inverse() * it
  std::array<std::vector<std::vector<Eigen::Vector2d>>, 2> corners_px;
};

StereoBoardSet MakeStereoBoardSet(const StereoBoardOptions& options,
                                  const ProgressSink& progress = ProgressSink());

struct StereoSequenceOptions {
  // kRoom, kStreet: a gentle S-curve of path_length_m (<= 20 m) through the scene.
  // kCityBlock: num_laps laps of a closed loop of path_length_m (40 .. 400 m) along the street
  // around a block of buildings (engine/synth/city_block.h); num_frames spread evenly over the
  // laps (frame num_frames would be back at the start). Each lap keeps to a slightly different
  // line (up to 0.5 m either side of the centreline), so revisits see a place from near, not
  // identical, positions.
  enum class Environment { kRoom, kStreet, kCityBlock };
  Environment environment = Environment::kRoom;
  int num_frames = 40;
  double path_length_m = 6.0;     // the path's length; kCityBlock: one lap's
  int num_laps = 1;               // kCityBlock only
  double frame_interval_s = 0.1;  // timestamps i * interval
  // Revisits under other light: lap k is lit by LapLighting(k) (lap 0 as without this option),
  // changing gradually over the first 5 % of each lap so that tracking across the change holds.
  bool lighting_change = false;
  // Motion blur: each image is the mean over motion_blur_samples poses spread evenly over an
  // exposure of motion_blur_exposure_s centred on the frame's timestamp (0: none). Costs
  // motion_blur_samples renders per image.
  double motion_blur_exposure_s = 0.0;
  int motion_blur_samples = 5;
  double sensor_height_m = 1.0;   // of cam0 above the floor
  int width = 1024;
  int height = 768;
  std::optional<std::array<SynthCamera, 2>> cameras;
  Rigid3d cam0_from_cam1 = DefaultCam0FromCam1();
  RenderOptions render;
  uint64_t seed = 0;

  void Check() const;
};

struct StereoSequence {
  StereoSequenceOptions options;  // what it was made with
  StereoRig rig;
  std::array<SynthCamera, 2> cameras;
  Scene scene;                     // z-up world, floor at z = 0
  // "frame_000", ...: zero-padded to at least 3 digits and to the digits of the last index, so
  // that names sort in frame order ("frame_0999" before "frame_1000").
  std::vector<std::string> names;
  std::vector<double> timestamps_s;
  std::vector<Rigid3d> world_from_rig;  // the rig frame is cam0's frame
  std::vector<int> laps;                // each frame's lap (0 but for kCityBlock)
  std::array<std::vector<cv::Mat>, 2> images;
};

// The lighting of lap `lap` with StereoSequenceOptions::lighting_change: lap 0 the default
// (no change); then in turn a dim, warm light from a low sun, a bright, cool one from a high sun
// and a grey, overcast one, repeating.
Lighting LapLighting(int lap);

StereoSequence MakeStereoSequence(const StereoSequenceOptions& options,
                                  const ProgressSink& progress = ProgressSink());

// Receives each frame's index, name and images (cam0, cam1) as they are rendered.
using StereoFrameSink = std::function<void(int frame, const std::string& name,
                                           const cv::Mat& cam0_image, const cv::Mat& cam1_image)>;

// As MakeStereoSequence, but hands each frame's images to `sink` instead of keeping them (a long
// loop at full size does not fit in memory): the returned sequence has no images.
StereoSequence RenderStereoSequence(const StereoSequenceOptions& options,
                                    const StereoFrameSink& sink,
                                    const ProgressSink& progress = ProgressSink());

// The scenes of MakeStereoSequence, for tests that render their own views.
Scene MakeRoomScene(uint64_t seed);    // 10 m x 7 m x 2.8 m room with furniture and pillars
Scene MakeStreetScene(uint64_t seed);  // a street between building fronts, with poles and cars
// kCityBlock: engine/synth/city_block.h (MakeCityBlockScene, CityBlockLoop).

// Writes `image` as a PNG file at `path`, creating missing parent folders. Throws
// std::runtime_error when the file cannot be written.
void WritePng(const cv::Mat& image, const std::string& path);

}  // namespace omnirig::synth
