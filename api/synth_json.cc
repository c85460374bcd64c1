#include "api/synth_json.h"

#include <filesystem>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "api/camera_json.h"
#include "api/job_types.h"
#include "engine/slam/map_io.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

const char* StyleName(synth::TextureSpec::Style style) {
  switch (style) {
    case synth::TextureSpec::Style::kRich:
      return "rich";
    case synth::TextureSpec::Style::kSoft:
      return "soft";
    case synth::TextureSpec::Style::kPlain:
      return "plain";
  }
  return "unknown";
}

nlohmann::json Vector(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json Header(const std::string& preset, int width, int height) {
  return {{"format", "omnirig-synth"},
          {"version", 1},
          {"preset", preset},
          {"image_size", {width, height}}};
}

std::string PngName(const std::string& name) { return name + ".png"; }

nlohmann::json SynthCameraToJson(const synth::SynthCamera& camera) {
  nlohmann::json json = CameraToJson(camera.model);
  json["rim_radius_px"] = camera.rim_radius_px;
  json["hole_radius_px"] = camera.hole_radius_px;
  return json;
}

nlohmann::json BoardToJson(const synth::CheckerboardSpec& board) {
  nlohmann::json corners = nlohmann::json::array();
  for (const Eigen::Vector3d& corner : synth::BoardCorners(board))
    corners.push_back(Vector(corner));
  return {{"cols", board.cols},
          {"rows", board.rows},
          {"square_size_m", board.square_size_m},
          {"margin_m", board.margin_m},
          {"corners_in_board_m", corners}};
}

nlohmann::json SceneToJson(const synth::Scene& scene, const std::string& world_frame) {
  nlohmann::json primitives = nlohmann::json::array();
  for (const synth::PrimitiveInfo& primitive : scene.primitives()) {
    nlohmann::json json = {{"kind", synth::KindName(primitive.kind)},
                           {"name", primitive.name},
                           {"world_from_local", PoseToJson(primitive.world_from_local)},
                           {"size_m", Vector(primitive.size_m)}};
    if (primitive.board) {
      json["board"] = BoardToJson(*primitive.board);
    } else {
      json["texture"] = {{"style", StyleName(primitive.texture.style)},
                         {"seed", primitive.texture.seed},
                         {"color_rgb", Vector(primitive.texture.color_rgb)},
                         {"texel_size_m", primitive.texture.texel_size_m},
                         {"shapes_per_m2", primitive.texture.shapes_per_m2}};
    }
    primitives.push_back(json);
  }
  return {{"world_frame", world_frame},
          {"background_rgb", Vector(scene.background_rgb())},
          {"primitives", primitives}};
}

nlohmann::json StereoRigToJson(const StereoRig& rig,
                               const std::array<synth::SynthCamera, 2>& cameras) {
  nlohmann::json json = RigToJson(rig);
  json["cameras"]["cam0"] = SynthCameraToJson(cameras[0]);
  json["cameras"]["cam1"] = SynthCameraToJson(cameras[1]);
  return json;
}

}  // namespace

nlohmann::json CornersToJson(const std::vector<Eigen::Vector2d>& corners_px) {
  nlohmann::json json = nlohmann::json::array();
  for (const Eigen::Vector2d& pixel : corners_px) {
    json.push_back(pixel.allFinite() ? nlohmann::json{pixel.x(), pixel.y()} : nlohmann::json());
  }
  return json;
}

nlohmann::json MonoCalibrationSetToJson(const synth::MonoCalibrationSet& set) {
  nlohmann::json json = Header("mono-calib", set.camera.model.width, set.camera.model.height);
  json["camera"] = SynthCameraToJson(set.camera);
  json["board"] = BoardToJson(set.board);
  json["scene"] = SceneToJson(set.background, "camera");
  nlohmann::json images = nlohmann::json::array();
  for (size_t i = 0; i < set.names.size(); ++i) {
    images.push_back({{"name", set.names[i]},
                      {"file", PngName(set.names[i])},
                      {"cam_from_board", PoseToJson(set.cam_from_board[i])},
                      {"corners_px", CornersToJson(set.corners_px[i])}});
  }
  json["images"] = images;
  return json;
}

nlohmann::json StereoBoardSetToJson(const synth::StereoBoardSet& set) {
  nlohmann::json json = Header("stereo-board", set.rig.cam0.width, set.rig.cam0.height);
  json["rig"] = StereoRigToJson(set.rig, set.cameras);
  json["board"] = BoardToJson(set.board);
  json["scene"] = SceneToJson(set.background, "cam0");
  const Rigid3d cam1_from_cam0 = set.rig.cam0_from_cam1.Inverse();
  nlohmann::json pairs = nlohmann::json::array();
  for (size_t i = 0; i < set.names.size(); ++i) {
    pairs.push_back(
        {{"name", set.names[i]},
         {"files",
          {{"cam0", "cam0/" + PngName(set.names[i])}, {"cam1", "cam1/" + PngName(set.names[i])}}},
         {"cam0_from_board", PoseToJson(set.cam0_from_board[i])},
         {"cam1_from_board", PoseToJson(cam1_from_cam0 * set.cam0_from_board[i])},
         {"corners_px",
          {{"cam0", CornersToJson(set.corners_px[0][i])},
           {"cam1", CornersToJson(set.corners_px[1][i])}}}});
  }
  json["pairs"] = pairs;
  return json;
}

nlohmann::json StereoSequenceToJson(const synth::StereoSequence& sequence,
                                    const std::string& environment) {
  const synth::StereoSequenceOptions& options = sequence.options;
  const bool loop = options.environment == synth::StereoSequenceOptions::Environment::kCityBlock;
  nlohmann::json json = Header(loop ? "stereo-loop" : "stereo-sequence", sequence.rig.cam0.width,
                               sequence.rig.cam0.height);
  json["rig"] = StereoRigToJson(sequence.rig, sequence.cameras);
  json["rig_frame"] = "cam0";
  json["environment"] = environment;
  if (loop) {
    json["loop"] = {{"length_m", options.path_length_m},
                    {"num_laps", options.num_laps},
                    {"lighting_change", options.lighting_change},
                    {"motion_blur_exposure_s", options.motion_blur_exposure_s},
                    {"motion_blur_samples", options.motion_blur_samples}};
  }
  json["scene"] = SceneToJson(sequence.scene, "world");
  nlohmann::json frames = nlohmann::json::array();
  for (size_t i = 0; i < sequence.names.size(); ++i) {
    const std::string& name = sequence.names[i];
    frames.push_back(
        {{"name", name},
         {"timestamp_s", sequence.timestamps_s[i]},
         {"files", {{"cam0", "cam0/" + PngName(name)}, {"cam1", "cam1/" + PngName(name)}}},
         {"world_from_rig", PoseToJson(sequence.world_from_rig[i])}});
    if (loop) frames.back()["lap"] = sequence.laps[i];
  }
  json["frames"] = frames;
  json["trajectory_file"] = "trajectory.tum";
  return json;
}

void WriteMonoCalibrationSet(const synth::MonoCalibrationSet& set, const std::string& dir) {
  const std::filesystem::path root(dir);
  std::filesystem::create_directories(root);
  for (size_t i = 0; i < set.images.size(); ++i) {
    synth::WritePng(set.images[i], (root / PngName(set.names[i])).string());
  }
  WriteTextFile(root / "ground_truth.json", MonoCalibrationSetToJson(set).dump(2) + "\n");
}

void WriteStereoBoardSet(const synth::StereoBoardSet& set, const std::string& dir) {
  const std::filesystem::path root(dir);
  for (int k = 0; k < 2; ++k) {
    const std::filesystem::path folder = root / (k == 0 ? "cam0" : "cam1");
    std::filesystem::create_directories(folder);
    for (size_t i = 0; i < set.images[k].size(); ++i) {
      synth::WritePng(set.images[k][i], (folder / PngName(set.names[i])).string());
    }
  }
  WriteTextFile(root / "ground_truth.json", StereoBoardSetToJson(set).dump(2) + "\n");
}

void WriteStereoFrame(const std::string& name, const cv::Mat& cam0_image,
                      const cv::Mat& cam1_image, const std::string& dir) {
  const std::filesystem::path root(dir);
  synth::WritePng(cam0_image, (root / "cam0" / PngName(name)).string());
  synth::WritePng(cam1_image, (root / "cam1" / PngName(name)).string());
}

void WriteStereoSequenceGroundTruth(const synth::StereoSequence& sequence,
                                    const std::string& environment, const std::string& dir) {
  const std::filesystem::path root(dir);
  std::filesystem::create_directories(root);
  WriteTextFile(root / "ground_truth.json",
                StereoSequenceToJson(sequence, environment).dump(2) + "\n");
  std::vector<slam::StampedPose> poses;
  for (size_t i = 0; i < sequence.world_from_rig.size(); ++i) {
    poses.push_back({sequence.timestamps_s[i], sequence.world_from_rig[i]});
  }
  slam::WriteTum(root / "trajectory.tum", poses);
}

namespace {

int FourCcOfFormat(const std::string& format) {
  if (format == "mp4") return cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  if (format == "avi") return cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  if (format == "mkv") return cv::VideoWriter::fourcc('F', 'F', 'V', '1');
  throw InvalidArgument("video format must be mp4, avi or mkv, not '" + format + "'");
}

cv::Mat Bgr(const cv::Mat& image) {
  if (image.channels() == 3) return image;
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  return bgr;
}

}  // namespace

void WriteStereoSequenceVideos(const synth::StereoSequence& sequence,
                               const std::string& environment, const std::string& dir,
                               const std::string& format, bool stacked) {
  const int fourcc = FourCcOfFormat(format);
  OMNIRIG_CHECK(sequence.timestamps_s.size() >= 2 && !sequence.images[0].empty(),
                "a video needs at least two frames");
  const double fps = 1.0 / (sequence.timestamps_s[1] - sequence.timestamps_s[0]);
  const std::filesystem::path root(dir);
  std::filesystem::create_directories(root);
  const cv::Size size = sequence.images[0][0].size();
  const std::vector<std::string> files =
      stacked ? std::vector<std::string>{"stacked." + format}
              : std::vector<std::string>{"cam0." + format, "cam1." + format};
  for (size_t f = 0; f < files.size(); ++f) {
    const cv::Size frame_size(size.width, stacked ? 2 * size.height : size.height);
    cv::VideoWriter writer((root / files[f]).string(), cv::CAP_FFMPEG, fourcc, fps, frame_size);
    if (!writer.isOpened()) throw std::runtime_error("cannot write " + files[f]);
    for (size_t i = 0; i < sequence.images[0].size(); ++i) {
      if (!stacked) {
        writer.write(Bgr(sequence.images[f][i]));
        continue;
      }
      cv::Mat both;
      cv::vconcat(Bgr(sequence.images[0][i]), Bgr(sequence.images[1][i]), both);
      writer.write(both);
    }
  }
  WriteStereoSequenceGroundTruth(sequence, environment, dir);
}

void WriteStereoSequence(const synth::StereoSequence& sequence, const std::string& environment,
                         const std::string& dir) {
  for (int k = 0; k < 2; ++k) {
    std::filesystem::create_directories(std::filesystem::path(dir) / (k == 0 ? "cam0" : "cam1"));
  }
  for (size_t i = 0; i < sequence.names.size(); ++i) {
    WriteStereoFrame(sequence.names[i], sequence.images[0][i], sequence.images[1][i], dir);
  }
  WriteStereoSequenceGroundTruth(sequence, environment, dir);
}

}  // namespace omnirig::api
