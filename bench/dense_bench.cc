// bench_dense: dense 3D from one pair of the vertical rig (against its targets), next to
// cv::omnidir::stereoReconstruct (RECTIFY_PERSPECTIVE and RECTIFY_LONGLATI, each rectifying and
// running StereoSGBM) on the same renders, in the same run.
//
// Renders: the textured room of engine/synth/presets.h (MakeStereoSequence), 1024x768, image
// noise 1 grey level, the default rig (100 mm vertical baseline), 4 frames along the path. Each
// point is scored by its distance to the room's true surfaces (testing/slam/surface_distance.h)
// divided by its range from cam0. Azimuth coverage: the fraction of 1-degree bins of the angle
// around cam0's axis holding at least one point. Time: seconds per pair on the threads given
// (default 2), after the per-rig set-up (omnirig's rectification tables, timed separately; the
// peer has no such split and rebuilds its maps per call).
//
// Per stage: process CPU seconds, taken at the engine's progress reports (rectify + masks, SGBM,
// confidence, then the pair-level fit check + triangulation + panoramas), and the writing of the
// job's artifacts (NAME_range.tiff, NAME_range.png, the pair's PLY, into a temporary folder)
// with the job's functions, here one after the other so that each stage's CPU is its own.
// Then the stereo_reconstruct job itself (api/stereo_job.cc) on the same renders, end to end:
// it reads the images and writes pair k's artifacts while it matches pair k + 1; once with the
// pairs' own clouds, once with a .tum trajectory (cloud.ply of all pairs as well).
//
// --no-peer runs omnirig only (for profiling).
//
// --block-size, --step-factor and --max-parallax-deg set DenseStereoOptions' block_size,
// grid.step_factor and max_parallax_deg (to measure what they cost and give).
//
// Usage: bench_dense [--frames N] [--threads N] [--no-peer] [--block-size N] [--step-factor F]
//                    [--max-parallax-deg D]

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <opencv2/ccalib/omnidir.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/stereo_job.h"
#include "engine/dense/dense_stereo.h"
#include "engine/dense/range_io.h"
#include "engine/geometry/ply.h"
#include "engine/slam/map_io.h"
#include "engine/synth/presets.h"
#include "testing/slam/surface_distance.h"

namespace omnirig {
namespace {

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// CPU seconds of the process (all threads): on a shared machine the wall time depends on the
// other processes' load, the CPU time much less.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

struct Score {
  double points = 0.0;  // summed over pairs
  double coverage = 0.0;
  std::vector<double> relative;  // distance to the surfaces / range, all pairs
  double seconds = 0.0;
  double cpu_seconds = 0.0;
  int pairs = 0;

  void Add(const std::vector<Eigen::Vector3d>& points_in_cam0, const synth::Scene& scene,
           const Rigid3d& world_from_cam0, double seconds_for_pair, double cpu_for_pair) {
    cpu_seconds += cpu_for_pair;
    std::vector<int> bins(360, 0);
    for (const Eigen::Vector3d& p : points_in_cam0) {
      const double range = p.norm();
      if (!(range > 1e-6) || !std::isfinite(range)) continue;
      relative.push_back(slam::DistanceToSceneSurface(scene, world_from_cam0 * p) / range);
      double azimuth = std::atan2(p.y(), p.x()) * 180.0 / M_PI;
      if (azimuth < 0) azimuth += 360.0;
      ++bins[std::min(359, static_cast<int>(azimuth))];
    }
    points += static_cast<double>(points_in_cam0.size());
    coverage += std::count_if(bins.begin(), bins.end(), [](int n) { return n > 0; }) / 360.0;
    seconds += seconds_for_pair;
    ++pairs;
  }

  void Print(const char* name) {
    std::sort(relative.begin(), relative.end());
    const double median = relative.empty() ? NAN : relative[relative.size() / 2];
    const double within =
        relative.empty()
            ? 0.0
            : static_cast<double>(std::upper_bound(relative.begin(), relative.end(), 0.01) -
                                  relative.begin()) /
                  relative.size();
    std::printf("| %-48s | %11.0f | %6.1f %% | %7.3f %% | %7.1f %% | %6.3f | %6.3f |\n", name,
                points / pairs, 100.0 * coverage / pairs, 100.0 * median, 100.0 * within,
                seconds / pairs, cpu_seconds / pairs);
  }
};

// The rig in cv::omnidir's terms: K, D = (k1, k2, p1, p2), xi per camera, and (R, T) taking
// cam0's frame into cam1's.
struct PeerRig {
  cv::Mat k[2], d[2], xi[2], r, t;
};

PeerRig ToPeer(const StereoRig& rig) {
  PeerRig peer;
  for (int c = 0; c < 2; ++c) {
    const UnifiedIntrinsics& in = c == 0 ? rig.cam0.intrinsics : rig.cam1.intrinsics;
    peer.k[c] = (cv::Mat_<double>(3, 3) << in.gamma_u(), in.gamma_u() * in.alpha(), in.u0(), 0,
                 in.gamma_v(), in.v0(), 0, 0, 1);
    peer.d[c] = (cv::Mat_<double>(1, 4) << in.k(1), in.k(2), in.k(3), in.k(4));
    peer.xi[c] = (cv::Mat_<double>(1, 1) << in.xi());
  }
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  const Eigen::Matrix3d r = cam1_from_cam0.rotation.toRotationMatrix();
  peer.r = cv::Mat(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) peer.r.at<double>(i, j) = r(i, j);
  peer.t = (cv::Mat_<double>(3, 1) << cam1_from_cam0.translation.x(),
            cam1_from_cam0.translation.y(), cam1_from_cam0.translation.z());
  return peer;
}

// One cv::omnidir::stereoReconstruct call; its points (in the first camera's rectified frame,
// rotated by stereoRectify's R1) turned back into cam0's frame.
std::vector<Eigen::Vector3d> PeerReconstruct(const PeerRig& peer, const cv::Mat& image0,
                                             const cv::Mat& image1, int flag, cv::Size size,
                                             const cv::Mat& k_new, int num_disparities,
                                             int window) {
  cv::Mat disparity, rec0, rec1, cloud;
  cv::omnidir::stereoReconstruct(image0, image1, peer.k[0], peer.d[0], peer.xi[0], peer.k[1],
                                 peer.d[1], peer.xi[1], peer.r, peer.t, flag, num_disparities,
                                 window, disparity, rec0, rec1, size, k_new, cloud,
                                 cv::omnidir::XYZ);
  cv::Mat r1, r2;
  cv::omnidir::stereoRectify(peer.r, peer.t, r1, r2);
  Eigen::Matrix3d cam0_from_rect;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) cam0_from_rect(i, j) = r1.at<double>(j, i);
  std::vector<Eigen::Vector3d> points;
  points.reserve(cloud.total());
  for (size_t i = 0; i < cloud.total(); ++i) {
    const cv::Vec3f p = cloud.at<cv::Vec3f>(static_cast<int>(i));
    points.push_back(cam0_from_rect * Eigen::Vector3d(p[0], p[1], p[2]));
  }
  return points;
}

// The stereo_reconstruct job itself (api/stereo_job.cc) on the renders saved as PNG in a
// temporary dataset: reading the images, matching, the result's figures and the artifacts
// (NAME_range.tiff, NAME_range.png, cloud_NAME.ply; with `merged`, the dataset holds the true
// trajectory as a .tum file and the job also writes cloud.ply of all pairs). The job writes pair
// k's files while it matches pair k + 1. Prints wall and CPU seconds per pair.
void RunJob(const synth::StereoSequence& sequence, int num_frames,
            const dense::DenseStereoOptions& dense_options, bool merged) {
  const std::filesystem::path root =
      std::filesystem::temp_directory_path() / "omnirig_bench_dense_job";
  std::filesystem::remove_all(root);
  api::JobContext context;
  context.dataset_dir = root / "data";
  context.output_dir = root / "out";
  for (const char* dir : {"data/cam0", "data/cam1", "out"}) {
    std::filesystem::create_directories(root / dir);
  }
  std::vector<slam::StampedPose> poses;
  for (int f = 0; f < num_frames; ++f) {
    for (int c = 0; c < 2; ++c) {
      const std::string name = "cam" + std::to_string(c) + "/" + sequence.names[f] + ".png";
      cv::imwrite((context.dataset_dir / name).string(), sequence.images[c][f]);
      context.image_names.push_back(name);
    }
    poses.push_back({static_cast<double>(f), sequence.world_from_rig[f]});
  }
  if (merged) {
    slam::WriteTum(context.dataset_dir / "truth.tum", poses);
    context.image_names.push_back("truth.tum");
  }
  std::sort(context.image_names.begin(), context.image_names.end());
  const nlohmann::json rig = api::RigToJson(sequence.rig);
  context.load_result = [&rig](const std::string&) { return rig; };
  nlohmann::json params = api::DenseStereoOptionsToJson(dense_options);
  params["rig"] = "rig";
  const auto start = std::chrono::steady_clock::now();
  const double cpu = CpuSeconds();
  const nlohmann::json result = api::RunStereoReconstructJob(params, context);
  const double s = Seconds(start), cpu_s = CpuSeconds() - cpu;
  std::printf(
      "omnirig stereo_reconstruct job, %d pairs%s: %.3f s/pair wall, %.3f CPU s/pair, "
      "%zu points, artifact %s\n",
      num_frames, merged ? " + cloud.ply of all (.tum)" : "", s / num_frames, cpu_s / num_frames,
      result["num_points"].get<size_t>(), result["artifact"].get<std::string>().c_str());
  std::filesystem::remove_all(root);
}

int Run(int num_frames, int threads, bool with_peer,
        const dense::DenseStereoOptions& dense_options) {
  cv::setNumThreads(threads);
  synth::StereoSequenceOptions options;
  options.num_frames = num_frames;
  options.render.noise_sigma = 1.0;
  options.seed = 3;
  std::printf("rendering %d pairs of the room at 1024x768...\n", num_frames);
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  std::printf("threads: %d (cv::setNumThreads)\n\n", threads);

  auto start = std::chrono::steady_clock::now();
  const dense::DenseStereo dense(sequence.rig, dense_options);
  const double setup_s = Seconds(start);
  // A second job of the same rig finds the tables built (SharedRectifier).
  start = std::chrono::steady_clock::now();
  const double again_s = (dense::DenseStereo(sequence.rig, dense_options), Seconds(start));
  Score ours;
  dense::DensePairResult::Seconds stages;
  // CPU seconds per stage, summed over the pairs, keyed by the engine's progress stage (the
  // stage that ends at the next report) and the artifact written.
  std::map<std::string, double> stage_cpu;
  const std::filesystem::path out_dir =
      std::filesystem::temp_directory_path() / "omnirig_bench_dense";
  std::filesystem::create_directories(out_dir);
  for (int f = 0; f < num_frames; ++f) {
    start = std::chrono::steady_clock::now();
    const double cpu = CpuSeconds();
    double stage_start = cpu;
    std::string stage;
    ProgressSink progress;
    progress.report = [&](double, const std::string& next, const std::string&) {
      const double now = CpuSeconds();
      if (!stage.empty()) stage_cpu[stage] += now - stage_start;
      stage = next;
      stage_start = now;
    };
    const dense::DensePairResult result =
        dense.Reconstruct(sequence.images[0][f], sequence.images[1][f], progress);
    const auto timed = [&](const std::string& name, const auto& write) {
      const double before = CpuSeconds();
      write();
      stage_cpu[name] += CpuSeconds() - before;
    };
    timed("write tiff",
          [&] { dense::WriteRangeTiff(out_dir / "pair_range.tiff", result.range_m); });
    timed("write png", [&] { dense::WriteRangePng(out_dir / "pair_range.png", result.range_m); });
    timed("write ply", [&] {
      PlyCloud cloud;
      cloud.has_confidence = true;
      cloud.positions.reserve(result.points.size());
      cloud.colours.reserve(result.points.size());
      cloud.confidence.reserve(result.points.size());
      for (const dense::DensePoint& p : result.points) {
        cloud.positions.push_back(p.point_in_cam0);
        cloud.colours.push_back(p.rgb);
        cloud.confidence.push_back(p.confidence);
      }
      WritePly(out_dir / "cloud.ply", cloud);
    });
    const double s = Seconds(start), cpu_s = CpuSeconds() - cpu;
    stages.rectify += result.seconds.rectify / num_frames;
    stages.match += result.seconds.match / num_frames;
    stages.confidence += result.seconds.confidence / num_frames;
    stages.epipolar += result.seconds.epipolar / num_frames;
    stages.triangulate += result.seconds.triangulate / num_frames;
    std::vector<Eigen::Vector3d> points;
    points.reserve(result.points.size());
    for (const dense::DensePoint& p : result.points)
      points.push_back(p.point_in_cam0.cast<double>());
    ours.Add(points, sequence.scene, sequence.world_from_rig[f], s, cpu_s);
  }
  std::filesystem::remove_all(out_dir);

  const PeerRig peer = ToPeer(sequence.rig);
  struct PeerSetting {
    const char* name;
    int flag;
    cv::Size size;
    cv::Mat k_new;
    int disparities, window;
  };
  const cv::Size perspective(1024, 768), longlati(2048, 768);
  const std::vector<PeerSetting> settings = {
      {"cv::omnidir PERSPECTIVE + SGBM (f = w/4, 80, 5)", cv::omnidir::RECTIFY_PERSPECTIVE,
       perspective, (cv::Mat_<double>(3, 3) << 256, 0, 512, 0, 256, 384, 0, 0, 1), 80, 5},
      {"cv::omnidir PERSPECTIVE + SGBM (f = w/3, 96, 7)", cv::omnidir::RECTIFY_PERSPECTIVE,
       perspective, (cv::Mat_<double>(3, 3) << 341, 0, 512, 0, 341, 384, 0, 0, 1), 96, 7},
      {"cv::omnidir LONGLATI + SGBM (2048x768, 80, 5)", cv::omnidir::RECTIFY_LONGLATI, longlati,
       (cv::Mat_<double>(3, 3) << 2048 / M_PI, 0, 0, 0, 768 / M_PI, 0, 0, 0, 1), 80, 5},
      {"cv::omnidir LONGLATI + SGBM (2048x768, 360, 80, 5)", cv::omnidir::RECTIFY_LONGLATI,
       longlati, (cv::Mat_<double>(3, 3) << 2048 / M_PI, 0, 0, 0, 768 / (2 * M_PI), 0, 0, 0, 1), 80,
       5},
  };
  std::printf("| %-48s | %11s | %8s | %9s | %9s | %6s | %6s |\n", "method", "points/pair",
              "azimuth", "median/r", "within 1%", "s/pair", "CPU s");
  std::printf("|%s|%s|%s|%s|%s|%s|%s|\n", std::string(50, '-').c_str(),
              std::string(13, '-').c_str(), std::string(10, '-').c_str(),
              std::string(11, '-').c_str(), std::string(11, '-').c_str(),
              std::string(8, '-').c_str(), std::string(8, '-').c_str());
  ours.Print("omnirig dense (spherical grid + SGBM + ZNCC)");
  for (const PeerSetting& setting : with_peer ? settings : std::vector<PeerSetting>()) {
    Score score;
    for (int f = 0; f < num_frames; ++f) {
      start = std::chrono::steady_clock::now();
      const double cpu = CpuSeconds();
      const std::vector<Eigen::Vector3d> points =
          PeerReconstruct(peer, sequence.images[0][f], sequence.images[1][f], setting.flag,
                          setting.size, setting.k_new, setting.disparities, setting.window);
      const double s = Seconds(start), cpu_s = CpuSeconds() - cpu;
      score.Add(points, sequence.scene, sequence.world_from_rig[f], s, cpu_s);
    }
    score.Print(setting.name);
  }
  std::printf("\nomnirig per pair, CPU s by stage (end to end, artifacts written):");
  for (const auto& [name, seconds] : stage_cpu)
    std::printf(" %s %.3f,", name.c_str(), seconds / num_frames);
  std::printf(
      "\nomnirig per pair, wall s by stage: rectify + masks %.3f, SGBM %.3f, confidence "
      "%.3f, epipolar fit check %.3f, triangulate + panoramas %.3f\n",
      stages.rectify, stages.match, stages.confidence, stages.epipolar, stages.triangulate);
  std::printf(
      "omnirig: grid %d x %d cells (step %.5f rad), %d disparities; rectification "
      "tables built once per rig in %.3f s (wall; %.4f s for the next job of the rig)\n",
      dense.rectifier().rows(), dense.rectifier().cols(), dense.rectifier().theta_step_rad(),
      dense.num_disparities(), setup_s, again_s);
  std::printf("\n");
  RunJob(sequence, num_frames, dense_options, false);
  RunJob(sequence, num_frames, dense_options, true);
  return 0;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  int frames = 4, threads = 2;
  bool with_peer = true;
  omnirig::dense::DenseStereoOptions options;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--no-peer")) with_peer = false;
    if (i + 1 >= argc) continue;
    if (!std::strcmp(argv[i], "--frames"))
      frames = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--threads"))
      threads = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--block-size"))
      options.block_size = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--step-factor"))
      options.grid.step_factor = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--max-parallax-deg"))
      options.max_parallax_deg = std::atof(argv[++i]);
  }
  options.Check();
  return omnirig::Run(frames, threads, with_peer, options);
}
