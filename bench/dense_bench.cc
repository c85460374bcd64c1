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
// Sets of renders, each reported in its own table: the development room (the renders the
// method and its options were developed and tuned on), the same room with the held-out set's
// kind of noise at its own levels (NoisyRoom: more sensor noise and JPEG; a development set,
// tuned on) and the held-out lounge
// (testing/dense/held_out_scenes.h: other textures and scales, JPEG 85-95, sensor noise 2-3,
// vignetting, blur, a low warm sun), never used for tuning. Per set: omnirig (the default and,
// for comparison, SGBM's own sub-pixel disparity without the refinement), the peer, the
// sub-cell bias (pixel locking), the fraction of points within 1 and 2 of their range std of the
// true range along their ray, and the merged cloud of the pairs placed by their true poses,
// fused as the stereo job fuses them.
//
// The floor: the held-out lounge again without sensor noise and JPEG, and the image noise's share
// of the error on the noisy sets against their clean renders (PrintNoiseFloor; --no-floor skips
// the clean lounge and its figures).
//
// --no-peer runs omnirig only (for profiling); --no-job skips the job's runs;
// --development-only runs the development sets only (tuning); --calibrate-std fits the range
// std's two parameters (disparity_std_cells, disparity_std_scale) on the development sets (the
// room and the noisy room).
//
// --block-size, --sgbm-p1, --sgbm-p2, --refine-window, --step-factor, --max-parallax-deg,
// --min-confidence and --max-relative-range-std set DenseStereoOptions' block_size,
// smoothness_p1, smoothness_p2, refine_window_cells, grid.step_factor, max_parallax_deg,
// min_confidence and max_relative_range_std (to measure what they cost and give).
//
// --job-only runs the stereo_reconstruct job's two runs only (its wall time, A/B against
// another build under the same load).
//
// --job-rounds N runs only the job against the peer's first matching in N alternating rounds
// (RunJobRounds) and prints the median ratio; with --merged, the job that also writes the merged
// cloud of the pairs.
// Usage: bench_dense [--frames N] [--threads N] [--no-peer] [--no-job] [--job-only]
//                    [--job-rounds N [--merged]] [--development-only]
//                    [--calibrate-std] [--block-size N] [--sgbm-p1 N] [--sgbm-p2 N]
//                    [--refine-window N] [--step-factor F]
//                    [--max-parallax-deg D]
//                    [--no-floor] [--disparity-std-cells C]
//                    [--disparity-std-scale S] [--min-confidence C]
//                    [--max-relative-range-std S]

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <unordered_set>
#include <vector>

#include <opencv2/ccalib/omnidir.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "api/camera_json.h"
#include "api/stereo_job.h"
#include "engine/dense/dense_map.h"
#include "engine/dense/dense_stereo.h"
#include "engine/dense/range_io.h"
#include "engine/features/image.h"
#include "engine/features/mirror_mask.h"
#include "engine/geometry/ply.h"
#include "engine/slam/map_io.h"
#include "engine/synth/presets.h"
#include "engine/util/allocator.h"
#include "testing/dense/held_out_scenes.h"
#include "testing/slam/surface_distance.h"

namespace omnirig {
namespace {

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// CPU seconds of the process (all threads): on a shared machine the wall time depends on the
// other processes' load, the CPU time much less.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

// FNV-1a of a cloud's vertices (positions, colours, confidence, range std), for comparing runs.
uint64_t CloudHash(const PlyCloud& cloud) {
  uint64_t hash = 0xcbf29ce484222325ull;
  const auto add = [&hash](const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) hash = (hash ^ p[i]) * 0x100000001b3ull;
  };
  add(cloud.positions.data(), cloud.positions.size() * sizeof(Eigen::Vector3f));
  add(cloud.colours.data(), cloud.colours.size() * 3);
  add(cloud.confidence.data(), cloud.confidence.size() * sizeof(float));
  add(cloud.range_std_m.data(), cloud.range_std_m.size() * sizeof(float));
  return hash;
}

// The scene and poses a set of pairs is scored against.
struct BenchSet {
  std::string name;
  bool held_out = false;  // never used to choose a method or tune an option
  synth::Scene scene;
  StereoRig rig;
  std::vector<Rigid3d> world_from_rig;
  std::array<std::vector<cv::Mat>, 2> images;
};

struct Score {
  double points = 0.0;  // summed over pairs
  double coverage = 0.0;
  std::vector<double> relative;  // distance to the surfaces / range, all pairs
  // |range - true range along the ray| / the point's range std (omnirig only).
  std::vector<double> z;
  double seconds = 0.0;
  double cpu_seconds = 0.0;
  int pairs = 0;

  void Add(const std::vector<Eigen::Vector3d>& points_in_cam0, const synth::Scene& scene,
           const Rigid3d& world_from_cam0, double seconds_for_pair, double cpu_for_pair,
           const std::vector<float>& range_std_m = {}) {
    cpu_seconds += cpu_for_pair;
    std::vector<int> bins(360, 0);
    const Eigen::Vector3d centre = world_from_cam0.translation;
    for (size_t i = 0; i < points_in_cam0.size(); ++i) {
      const Eigen::Vector3d& p = points_in_cam0[i];
      const double range = p.norm();
      if (!(range > 1e-6) || !std::isfinite(range)) continue;
      relative.push_back(slam::DistanceToSceneSurface(scene, world_from_cam0 * p) / range);
      if (!range_std_m.empty() && range_std_m[i] > 0.f) {
        const double truth =
            slam::RangeToSceneSurface(scene, centre, world_from_cam0.rotation * (p / range));
        z.push_back(std::abs(range - truth) / range_std_m[i]);
      }
      double azimuth = std::atan2(p.y(), p.x()) * 180.0 / M_PI;
      if (azimuth < 0) azimuth += 360.0;
      ++bins[std::min(359, static_cast<int>(azimuth))];
    }
    points += static_cast<double>(points_in_cam0.size());
    coverage += std::count_if(bins.begin(), bins.end(), [](int n) { return n > 0; }) / 360.0;
    seconds += seconds_for_pair;
    ++pairs;
  }

  static double FractionAtMost(const std::vector<double>& sorted, double limit) {
    if (sorted.empty()) return 0.0;
    return static_cast<double>(std::upper_bound(sorted.begin(), sorted.end(), limit) -
                               sorted.begin()) /
           sorted.size();
  }

  void Print(const std::string& name) {
    std::sort(relative.begin(), relative.end());
    std::sort(z.begin(), z.end());
    const double median = relative.empty() ? NAN : relative[relative.size() / 2];
    const double within = FractionAtMost(relative, 0.01);
    std::string std_fractions = "      -      ";
    if (!z.empty()) {
      char buffer[64];
      std::snprintf(buffer, sizeof(buffer), "%4.1f / %4.1f %%", 100.0 * FractionAtMost(z, 1.0),
                    100.0 * FractionAtMost(z, 2.0));
      std_fractions = buffer;
    }
    std::printf("| %-50s | %11.0f | %6.1f %% | %7.3f %% | %7.1f %% | %s | %6.3f | %6.3f |\n",
                name.c_str(), points / pairs, 100.0 * coverage / pairs, 100.0 * median,
                100.0 * within, std_fractions.c_str(), seconds / pairs, cpu_seconds / pairs);
  }
};

// Pixel locking: SGBM's sub-cell disparity drawn towards whole cells. From each point's range,
// its disparity d = parallax / step (the grid's law of sines inverted) and the true one from the
// true range along its ray; prints the histogram of d's fractional part (uniform when unbiased)
// and the mean error d - d_true by the true disparity's fractional part (flat when unbiased).
struct SubCellBias {
  std::array<double, 8> estimated_fraction{};
  std::array<double, 8> error_sum{}, error_count{};
  std::vector<double> abs_error;
  // Per point: |disparity error| and the point's range std in disparity cells (its range std
  // over d range / d disparity), for --calibrate-std.
  std::vector<std::pair<double, double>> error_and_std_cells;

  void Add(const std::vector<dense::DensePoint>& points, const dense::SphericalRectifier& grid,
           const synth::Scene& scene, const Rigid3d& world_from_cam0) {
    const Eigen::Vector3d baseline_dir = grid.cam0_from_grid().col(2);
    const double b = grid.baseline_m(), step = grid.theta_step_rad();
    const auto disparity = [&](double range, double theta) {
      return (std::atan2(range * std::sin(theta), range * std::cos(theta) - b) - theta) / step;
    };
    for (const dense::DensePoint& point : points) {
      const Eigen::Vector3d p = point.point_in_cam0.cast<double>();
      const double range = p.norm();
      const double theta = std::acos(std::clamp(p.dot(baseline_dir) / range, -1.0, 1.0));
      const double truth = slam::RangeToSceneSurface(scene, world_from_cam0.translation,
                                                     world_from_cam0.rotation * (p / range));
      if (!std::isfinite(truth)) continue;
      const double d = disparity(range, theta), d_true = disparity(truth, theta);
      const double error = d - d_true;
      abs_error.push_back(std::abs(error));
      const double parallax = d * step;
      const double range_per_cell = b * std::sin(theta) / std::pow(std::sin(parallax), 2) * step;
      error_and_std_cells.emplace_back(std::abs(error), point.range_std_m / range_per_cell);
      estimated_fraction[std::min(7, static_cast<int>(8 * (d - std::floor(d))))] += 1;
      if (std::abs(error) > 1.0) continue;  // a wrong match, not a sub-cell bias
      const int bin = std::min(7, static_cast<int>(8 * (d_true - std::floor(d_true))));
      error_sum[bin] += error;
      error_count[bin] += 1;
    }
  }

  void Print(const std::string& name) {
    double total = 0.0;
    for (double n : estimated_fraction) total += n;
    std::sort(abs_error.begin(), abs_error.end());
    std::printf("%s: disparity error (cells) median |e| %.3f, 90th percentile %.3f\n", name.c_str(),
                abs_error.empty() ? NAN : abs_error[abs_error.size() / 2],
                abs_error.empty() ? NAN : abs_error[abs_error.size() * 9 / 10]);
    std::printf(
        "  share of points by the estimated disparity's fraction (1/8 bins, 12.5 %% each "
        "if unbiased):");
    for (double n : estimated_fraction) std::printf(" %.1f", 100.0 * n / std::max(1.0, total));
    std::printf("\n  mean error (cells) by the true disparity's fraction (0 if unbiased):    ");
    for (int i = 0; i < 8; ++i) {
      std::printf(" %+.3f", error_count[i] > 0 ? error_sum[i] / error_count[i] : NAN);
    }
    std::printf("\n");
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
// k's files while it matches the next pairs. Prints wall and CPU seconds per pair (with
// `print`); returns the wall seconds per pair.
double RunJob(const synth::StereoSequence& sequence, int num_frames,
              const dense::DenseStereoOptions& dense_options, bool merged, bool print = true) {
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
  if (print) {
    std::printf(
        "omnirig stereo_reconstruct job, %d pairs%s: %.3f s/pair wall, %.3f CPU s/pair, "
        "%zu points, artifact %s\n",
        num_frames, merged ? " + cloud.ply of all (.tum)" : "", s / num_frames,
        cpu_s / num_frames, result["num_points"].get<size_t>(),
        result["artifact"].get<std::string>().c_str());
  }
  std::filesystem::remove_all(root);
  return s / num_frames;
}

// --calibrate-std: the per-point disparity std is sqrt(floor^2 + (scale * fit_std)^2), fit_std
// the refinement's least-squares std (its residual); run with floor ~0 and scale 1, each point's
// std in cells is its fit's std. Grid search of (floor, scale) for 68 % of the points within 1
// std and 95 % within 2 on every development set (squared misses summed over the sets).
std::pair<double, double> WithinStd(const SubCellBias& bias, double floor, double scale) {
  size_t in1 = 0, in2 = 0;
  for (const auto& [error, fit] : bias.error_and_std_cells) {
    const double std_cells = std::sqrt(floor * floor + scale * scale * fit * fit);
    in1 += error <= std_cells;
    in2 += error <= 2.0 * std_cells;
  }
  const double n = std::max<size_t>(1, bias.error_and_std_cells.size());
  return {in1 / n, in2 / n};
}

void CalibrateStd(const std::vector<std::pair<std::string, SubCellBias>>& sets) {
  double best_cost = 1e9, best_floor = 0, best_scale = 0;
  for (double floor = 0.0; floor <= 0.4001; floor += 0.01) {
    for (double scale = 0.0; scale <= 6.0001; scale += 0.1) {
      double cost = 0.0;
      for (const auto& [name, bias] : sets) {
        const auto [f1, f2] = WithinStd(bias, floor, scale);
        cost += (f1 - 0.68) * (f1 - 0.68) + (f2 - 0.95) * (f2 - 0.95);
      }
      if (cost < best_cost) {
        best_cost = cost;
        best_floor = floor;
        best_scale = scale;
      }
    }
  }
  std::printf("std calibration: disparity_std_cells %.2f, disparity_std_scale %.1f\n", best_floor,
              best_scale);
  for (const auto& [name, bias] : sets) {
    const auto [f1, f2] = WithinStd(bias, best_floor, best_scale);
    std::printf("    %s: %.1f %% within 1 std, %.1f %% within 2 std\n", name.c_str(), 100.0 * f1,
                100.0 * f2);
  }
}

// The merged cloud of a set's pairs placed by their true poses: fused (MergedCloudOptions, as
// the stereo job writes cloud.ply) and, for comparison, all the pairs' points appended. Each
// point's distance to the true surfaces relative to its range from the nearest pair: median,
// within 1 %, and the 95th percentile (half the thickness of the layer that holds 95 % of the
// points); points per square metre of surface (the surface area: the 5 cm cells the fused
// points occupy, times 25 cm^2).
// The 5 cm cell of a point, as a key.
int64_t CellKey(const Eigen::Vector3d& p) {
  const Eigen::Vector3i cell = (p / 0.05).array().floor().cast<int>();
  return (static_cast<int64_t>(cell.x() + 100000) << 40) ^
         (static_cast<int64_t>(cell.y() + 100000) << 20) ^ (cell.z() + 100000);
}

struct MergedScore {
  std::vector<double> relative;
  // The points whose 5 cm cell holds points of at least two pairs (`pair_cells`): where several
  // pairs see one surface, the contract's layer.
  std::vector<double> relative_shared;
  size_t points = 0;
  double area_m2 = 0.0;
  size_t tail_front = 0, tail_behind = 0;

  void Score(const std::vector<Eigen::Vector3f>& points_in_world, const synth::Scene& scene,
             const std::vector<Rigid3d>& world_from_rig,
             const std::vector<std::unordered_set<int64_t>>& pair_cells) {
    points = points_in_world.size();
    std::unordered_set<int64_t> cells;
    for (const Eigen::Vector3f& pf : points_in_world) {
      const Eigen::Vector3d p = pf.cast<double>();
      double range = std::numeric_limits<double>::infinity();
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const Rigid3d& pose : world_from_rig) {
        if ((p - pose.translation).norm() < range) {
          range = (p - pose.translation).norm();
          centre = pose.translation;
        }
      }
      relative.push_back(slam::DistanceToSceneSurface(scene, p) / range);
      int num_pairs = 0;
      for (const std::unordered_set<int64_t>& cells_of_pair : pair_cells) {
        num_pairs += cells_of_pair.count(CellKey(p)) ? 1 : 0;
      }
      if (num_pairs >= 2) relative_shared.push_back(relative.back());
      if (relative.back() > 0.015) {
        const double truth = slam::RangeToSceneSurface(scene, centre, (p - centre) / range);
        (range < truth ? tail_front : tail_behind) += 1;
      }
      const Eigen::Vector3i cell = (p / 0.05).array().floor().cast<int>();
      cells.insert((static_cast<int64_t>(cell.x() + 100000) << 40) ^
                   (static_cast<int64_t>(cell.y() + 100000) << 20) ^ (cell.z() + 100000));
    }
    area_m2 = 0.0025 * cells.size();
    std::sort(relative.begin(), relative.end());
    std::sort(relative_shared.begin(), relative_shared.end());
  }

  void Print(const char* name) const {
    const auto at = [&](double q) {
      return relative.empty() ? NAN
                              : relative[std::min(relative.size() - 1,
                                                  static_cast<size_t>(q * relative.size()))];
    };
    std::printf(
        "%s: %zu points, median %.3f %% of range, %.1f %% within 1 %%, 95th percentile "
        "%.3f %% (layer %.2f %% thick), %.0f points per m^2 of %.1f m^2\n",
        name, points, 100.0 * at(0.5), 100.0 * Score::FractionAtMost(relative, 0.01),
        100.0 * at(0.95), 200.0 * at(0.95), points / std::max(area_m2, 1e-9), area_m2);
    std::printf("    off by > 1.5 %%: %zu in front of the surface, %zu behind\n", tail_front,
                tail_behind);
    const auto shared_at = [&](double q) {
      return relative_shared.empty()
                 ? NAN
                 : relative_shared[std::min(relative_shared.size() - 1,
                                            static_cast<size_t>(q * relative_shared.size()))];
    };
    std::printf(
        "    where several pairs see the surface (5 cm cells with points of >= 2 pairs): %zu "
        "points, median %.3f %%, %.1f %% within 1 %%, layer %.2f %% thick\n",
        relative_shared.size(), 100.0 * shared_at(0.5),
        100.0 * Score::FractionAtMost(relative_shared, 0.01), 200.0 * shared_at(0.95));
  }
};

// The peer's settings: cv::omnidir::stereoReconstruct's two rectifications.
struct PeerSetting {
  const char* name;
  int flag;
  cv::Size size;
  cv::Mat k_new;
  int disparities, window;
};

std::vector<PeerSetting> PeerSettings() {
  const cv::Size perspective(1024, 768), longlati(2048, 768);
  return {
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
}

// The job (with `merged`, also the merged cloud of the pairs placed by a .tum trajectory) and
// the peer's first matching (PERSPECTIVE, f = w/4) on the same pairs in alternating rounds,
// after one job that pages its buffers in: the machine's speed drifts between runs, so each
// round's ratio compares the two at nearly the same time. Prints each round and the median.
void RunJobRounds(const synth::StereoSequence& sequence, int num_frames, int rounds,
                  const dense::DenseStereoOptions& dense_options, bool merged) {
  const PeerRig peer = ToPeer(sequence.rig);
  const PeerSetting setting = PeerSettings().front();
  RunJob(sequence, num_frames, dense_options, merged, false);
  std::vector<double> ratios;
  std::printf("\nthe job's time a pair%s against %s, %d pairs a round:\n",
              merged ? " (with the merged cloud)" : "", setting.name, num_frames);
  for (int round = 0; round < rounds; ++round) {
    const double job_s = RunJob(sequence, num_frames, dense_options, merged, false);
    const auto start = std::chrono::steady_clock::now();
    for (int f = 0; f < num_frames; ++f) {
      PeerReconstruct(peer, sequence.images[0][f], sequence.images[1][f], setting.flag,
                      setting.size, setting.k_new, setting.disparities, setting.window);
    }
    const double peer_s = Seconds(start) / num_frames;
    ratios.push_back(job_s / peer_s);
    std::printf("  round %d: job %.3f s, peer %.3f s, %.2fx\n", round + 1, job_s, peer_s,
                ratios.back());
  }
  std::sort(ratios.begin(), ratios.end());
  std::printf("  median of %d rounds: %.2fx (range %.2f-%.2fx)\n", rounds,
              ratios[ratios.size() / 2], ratios.front(), ratios.back());
}

void PrintTableHeader() {
  std::printf("| %-50s | %11s | %8s | %9s | %9s | %13s | %6s | %6s |\n", "method", "points/pair",
              "azimuth", "median/r", "within 1%", "in 1 / 2 std", "s/pair", "CPU s");
  std::printf(
      "|%s|%s|%s|%s|%s|%s|%s|%s|\n", std::string(52, '-').c_str(), std::string(13, '-').c_str(),
      std::string(10, '-').c_str(), std::string(11, '-').c_str(), std::string(11, '-').c_str(),
      std::string(15, '-').c_str(), std::string(8, '-').c_str(), std::string(8, '-').c_str());
}

// The merged cloud's options with a tighter range-std filter (0.9 % of range), for comparison.
dense::DenseMapOptions TightMergedOptions() {
  dense::DenseMapOptions options = dense::MergedCloudOptions();
  options.max_relative_range_std = 0.009;
  return options;
}

// One omnirig setting on a set's pairs.
// What bounds a pair's points: the grid's cells, those inside both mirror masks (the usable
// annulus), those SGBM matched (left-right consistent, unique, not a speckle), the matched ones
// by confidence, and the points (confident, range std <= DenseStereoOptions'
// max_relative_range_std); per pair.
struct PointFunnel {
  double grid = 0, mirror = 0, matched = 0, confidence_04 = 0, confident = 0, points = 0;
  int pairs = 0;
  void Add(const dense::DensePairResult& result) {
    grid += result.confidence.total();
    mirror += result.num_mirror_cells;
    matched += result.num_matched_cells;
    confidence_04 += cv::countNonZero(result.confidence >= 0.4);
    confident += cv::countNonZero(result.confidence >= 0.5);
    points += result.num_points;
    ++pairs;
  }
  void Print() const {
    const double n = std::max(pairs, 1);
    std::printf(
        "cells per pair: grid %.0f, inside both mirror masks %.0f (%.1f %%), matched %.0f "
        "(%.1f %% of those), confidence >= 0.4 %.0f, >= 0.5 (min_confidence) %.0f, points %.0f\n",
        grid / n, mirror / n, 100.0 * mirror / std::max(grid, 1.0), matched / n,
        100.0 * matched / std::max(mirror, 1.0), confidence_04 / n, confident / n, points / n);
  }
};

struct OmnirigRun {
  PointFunnel funnel;
  Score score;
  SubCellBias bias;
  dense::DensePairResult::Seconds stages;
  // CPU seconds per stage, summed over the pairs, keyed by the engine's progress stage (the
  // stage that ends at the next report) and the artifact written.
  std::map<std::string, double> stage_cpu;
  std::vector<Eigen::Vector3f> appended;  // every pair's points in the world
  std::vector<std::unordered_set<int64_t>> pair_cells;  // each pair's 5 cm cells (MergedScore)
  dense::DenseMap fused{dense::MergedCloudOptions()};
  dense::DenseMap fused_tight{TightMergedOptions()};
  double setup_s = 0.0, again_s = 0.0, from_disk_s = 0.0, from_disk_cpu_s = 0.0;
  double fuse_cpu_s = 0.0;  // the merged cloud's DenseMap::Add, all pairs
  double fuse_s = 0.0;      // the same, wall
  double cold_pair_s = 0.0;  // with `profile`: the first pair of the process, untimed in score
  std::vector<std::vector<dense::DensePoint>> clouds;  // each pair's points (its cam0 frame)
};

// The tables a later process of the service reads from its cache folder instead of building:
// wall and CPU seconds of SharedRectifier with the file written, the process-wide cache emptied
// first (it keeps two, so two tiny grids of another step push the rig's tables out).
void EvictSharedRectifiers(const StereoRig& rig) {
  for (double step : {0.049, 0.05}) {
    dense::SphericalGridOptions tiny;
    tiny.step_rad = step;
    dense::SharedRectifier(rig, tiny);
  }
}

void TimeTablesFromDisk(const BenchSet& set, const dense::DenseStereoOptions& dense_options,
                        const std::filesystem::path& tables_dir, OmnirigRun* run) {
  EvictSharedRectifiers(set.rig);
  dense::SharedRectifier(set.rig, dense_options.grid, tables_dir);  // the file, if not yet
  EvictSharedRectifiers(set.rig);
  const auto start = std::chrono::steady_clock::now();
  const double cpu = CpuSeconds();
  dense::SharedRectifier(set.rig, dense_options.grid, tables_dir);
  run->from_disk_s = Seconds(start);
  run->from_disk_cpu_s = CpuSeconds() - cpu;
}

// With `profile`, the artifacts written as the job writes them, timed by stage.
void RunOmnirig(const BenchSet& set, const dense::DenseStereoOptions& dense_options, bool profile,
                OmnirigRun* run) {
  const int num_frames = static_cast<int>(set.world_from_rig.size());
  const std::filesystem::path out_dir =
      std::filesystem::temp_directory_path() / "omnirig_bench_dense";
  std::filesystem::remove_all(out_dir);
  std::filesystem::create_directories(out_dir);
  auto start = std::chrono::steady_clock::now();
  const dense::DenseStereo dense(set.rig, dense_options, out_dir / "tables");
  run->setup_s = Seconds(start);
  // A second job of the same rig finds the tables built (SharedRectifier), a later process reads
  // them from the file the first one wrote.
  start = std::chrono::steady_clock::now();
  run->again_s = (dense::DenseStereo(set.rig, dense_options), Seconds(start));
  if (profile) TimeTablesFromDisk(set, dense_options, out_dir / "tables", run);
  // The service's process has matched pairs before (its earlier jobs): the first pair of this
  // process, whose buffers are all new pages, is timed on its own and the pairs are timed after.
  if (profile) {
    start = std::chrono::steady_clock::now();
    dense.Reconstruct(set.images[0][0], set.images[1][0]);
    run->cold_pair_s = Seconds(start);
  }
  for (int f = 0; f < num_frames; ++f) {
    start = std::chrono::steady_clock::now();
    const double cpu = CpuSeconds();
    double stage_start = cpu;
    std::string stage;
    ProgressSink progress;
    progress.report = [&](double, const std::string& next, const std::string&) {
      const double now = CpuSeconds();
      if (!stage.empty()) run->stage_cpu[stage] += now - stage_start;
      stage = next;
      stage_start = now;
    };
    const dense::DensePairResult result =
        dense.Reconstruct(set.images[0][f], set.images[1][f], progress);
    run->funnel.Add(result);
    const auto timed = [&](const std::string& name, const auto& write) {
      const double before = CpuSeconds();
      write();
      run->stage_cpu[name] += CpuSeconds() - before;
    };
    if (profile) {
      timed("write tiff",
            [&] { dense::WriteRangeTiff(out_dir / "pair_range.tiff", result.range_m); });
      timed("write png", [&] { dense::WriteRangePng(out_dir / "pair_range.png", result.range_m); });
      timed("write ply",
            [&] { WritePly(out_dir / "cloud.ply", dense::ToPlyCloud(result.points)); });
    }
    const double s = Seconds(start), cpu_s = CpuSeconds() - cpu;
    run->stages.rectify += result.seconds.rectify / num_frames;
    run->stages.match += result.seconds.match / num_frames;
    run->stages.confidence += result.seconds.confidence / num_frames;
    run->stages.epipolar += result.seconds.epipolar / num_frames;
    run->stages.refine += result.seconds.refine / num_frames;
    run->stages.triangulate += result.seconds.triangulate / num_frames;
    std::vector<Eigen::Vector3d> points;
    std::vector<float> range_std;
    points.reserve(result.points.size());
    range_std.reserve(result.points.size());
    run->pair_cells.emplace_back();
    for (const dense::DensePoint& p : result.points) {
      points.push_back(p.point_in_cam0.cast<double>());
      run->pair_cells.back().insert(CellKey(set.world_from_rig[f] * points.back()));
      range_std.push_back(p.range_std_m);
      run->appended.push_back((set.world_from_rig[f] * points.back()).cast<float>());
    }
    run->score.Add(points, set.scene, set.world_from_rig[f], s, cpu_s, range_std);
    run->bias.Add(result.points, dense.rectifier(), set.scene, set.world_from_rig[f]);
    const auto fuse_start = std::chrono::steady_clock::now();
    const double fuse_cpu = CpuSeconds();
    run->fused.Add(set.world_from_rig[f], result.points);
    run->fuse_cpu_s += CpuSeconds() - fuse_cpu;
    run->fuse_s += Seconds(fuse_start);
    run->clouds.push_back(result.points);
    run->fused_tight.Add(set.world_from_rig[f], result.points);
    if (f == 0 && profile) {
      std::printf(
          "omnirig: grid %d x %d cells (step %.5f rad), %d disparities; rectification "
          "tables built once per rig in %.3f s (wall; %.4f s for the next job of the rig in the "
          "process, %.3f s wall and %.3f CPU s read from the file for a later process); the "
          "process's first pair %.3f s wall (its buffers new pages; the table's rows are timed "
          "after it, as in a service that has run jobs before)\n\n",
          dense.rectifier().rows(), dense.rectifier().cols(), dense.rectifier().theta_step_rad(),
          dense.num_disparities(), run->setup_s, run->again_s, run->from_disk_s,
          run->from_disk_cpu_s, run->cold_pair_s);
    }
  }
  std::filesystem::remove_all(out_dir);
}

// omnirig (the default, and SGBM's own sub-pixel disparity for comparison) and the peer on one
// set of pairs; with `profile`, CPU per stage and the artifacts written as the job writes them.
void RunSet(const BenchSet& set, bool with_peer, bool profile,
            const dense::DenseStereoOptions& dense_options) {
  const int num_frames = static_cast<int>(set.world_from_rig.size());
  std::printf("\n## %s%s, %d pairs\n\n", set.name.c_str(),
              set.held_out ? " [HELD OUT: never used for tuning]" : " [development: tuned on]",
              num_frames);
  OmnirigRun ours, unrefined;
  RunOmnirig(set, dense_options, profile, &ours);
  dense::DenseStereoOptions sgbm_only = dense_options;
  sgbm_only.refine_subcell = false;
  sgbm_only.disparity_std_scale = 0.0;
  sgbm_only.disparity_std_cells = 0.25;  // the constant std used before the refinement
  RunOmnirig(set, sgbm_only, false, &unrefined);

  PrintTableHeader();
  ours.score.Print(std::string("omnirig dense") + (profile ? " (artifacts written)" : ""));
  unrefined.score.Print("omnirig dense, SGBM's sub-pixel only (no refine)");
  const PeerRig peer = ToPeer(set.rig);
  for (const PeerSetting& setting : with_peer ? PeerSettings() : std::vector<PeerSetting>()) {
    Score score;
    for (int f = 0; f < num_frames; ++f) {
      const auto start = std::chrono::steady_clock::now();
      const double cpu = CpuSeconds();
      const std::vector<Eigen::Vector3d> points =
          PeerReconstruct(peer, set.images[0][f], set.images[1][f], setting.flag, setting.size,
                          setting.k_new, setting.disparities, setting.window);
      const double s = Seconds(start), cpu_s = CpuSeconds() - cpu;
      score.Add(points, set.scene, set.world_from_rig[f], s, cpu_s);
    }
    score.Print(setting.name);
  }
  std::printf("\n");
  ours.funnel.Print();
  ours.bias.Print("omnirig sub-cell disparity, refined (default)");
  unrefined.bias.Print("omnirig sub-cell disparity, SGBM's sub-pixel only");
  std::printf("\nmerged cloud of the %d pairs placed by their true poses:\n", num_frames);
  MergedScore appended, fused, fused_tight;
  appended.Score(ours.appended, set.scene, set.world_from_rig, ours.pair_cells);
  auto start = std::chrono::steady_clock::now();
  double cpu = CpuSeconds();
  const PlyCloud fused_cloud = ours.fused.Cloud();
  const double cloud_cpu_s = CpuSeconds() - cpu, cloud_s = Seconds(start);
  start = std::chrono::steady_clock::now();
  cpu = CpuSeconds();
  const double fused_per_m2 = dense::PointsPerSquareMetre(fused_cloud.positions);
  const double density_cpu_s = CpuSeconds() - cpu, density_s = Seconds(start);
  fused.Score(fused_cloud.positions, set.scene, set.world_from_rig, ours.pair_cells);
  fused_tight.Score(ours.fused_tight.Cloud().positions, set.scene, set.world_from_rig,
                    ours.pair_cells);
  dense::DenseMapOptions plain_options = dense::MergedCloudOptions();
  plain_options.visibility_cell_rad = 0.0;
  dense::DenseMap plain(plain_options);
  for (size_t f = 0; f < ours.clouds.size(); ++f) plain.Add(set.world_from_rig[f], ours.clouds[f]);
  MergedScore voxels_only;
  voxels_only.Score(plain.Cloud().positions, set.scene, set.world_from_rig, ours.pair_cells);
  voxels_only.Print("  fused in voxels only (without the check along the other pairs' rays)");
  appended.Print("  appended (every pair's points)");
  fused.Print("  fused (MergedCloudOptions: 1 cm voxels, range std <= 2 %)");
  fused_tight.Print("  fused, range std <= 0.9 %");
  const size_t per_pair = std::max<size_t>(1, set.world_from_rig.size());
  std::printf(
      "  the job's fusion, CPU s: %.3f per pair adding its points, %.3f for the cloud of the "
      "voxels, %.3f for its points per m^2\n",
      ours.fuse_cpu_s / per_pair, cloud_cpu_s, density_cpu_s);
  std::printf(
      "  the job's fusion, wall s: %.3f per pair adding its points, %.3f for the cloud of the "
      "voxels, %.3f for its points per m^2\n",
      ours.fuse_s / per_pair, cloud_s, density_s);
  // Changes to the fusion's speed must leave its cloud bit for bit the same.
  std::printf("  the job's merged cloud: %zu points, %.6f points per m^2, FNV-1a %016llx\n",
              fused_cloud.size(), fused_per_m2,
              static_cast<unsigned long long>(CloudHash(fused_cloud)));
  if (profile) {
    std::printf("\nomnirig per pair, CPU s by stage (end to end, artifacts written):");
    for (const auto& [name, seconds] : ours.stage_cpu)
      std::printf(" %s %.3f,", name.c_str(), seconds / num_frames);
  }
  const dense::DensePairResult::Seconds& st = ours.stages;
  std::printf(
      "\nomnirig per pair, wall s by stage: rectify + masks %.3f, SGBM %.3f, confidence "
      "%.3f, epipolar fit check %.3f, sub-cell refinement %.3f, triangulate + panoramas %.3f\n",
      st.rectify, st.match, st.confidence, st.epipolar, st.refine, st.triangulate);
}

// The image noise's share of the error, with the clean renders of the same frames. On the grid,
// each camera's noise is the noisy render less the clean one (sensor noise and JPEG as the
// matcher sees them, after the resampling). Two figures per cell inside both mirrors whose ray
// hits the scene, for windows of 11 cells, of the refinement's (15) and of 21:
// - the Cramer-Rao bound of an unbiased disparity from the window under white noise of the
//   grid's std: (sigma_0^2 + sigma_1^2) / sum_W (dI/dc)^2 (dI/dc the clean cam0 grid's gradient
//   along the row), as a range std with the cell's true range; its expected median |error| is
//   0.674 std and its share within 1 % of range erf(0.01 r / (sqrt 2 std));
// - the error this noise itself puts into a least-squares fit of the window's disparity at the
//   true disparity, to first order: sum_W g (n0 - n1) / sum_W g^2, n1 cam1's noise at the cells
//   the true disparity pairs (correlated noise, JPEG's blocks and the resampling's, as it is).
// An estimator that reports N points a pair takes N cells; it can only know the cells'
// texture, not the noise's draw, so the N cells of the lowest bound are taken and the median
// of each figure over them printed: no window estimator's median on these cells falls below
// what the noise alone puts into it (the matching adds its own bias on top). And the same
// first-order error on the cells omnirig itself reports (the noisy pairs reconstructed with
// dense_options), in the refinement's window: what the noise alone puts into the points the
// product gives, which it chose by their windows' correlation rather than by their texture.
void PrintNoiseFloor(const BenchSet& noisy, const BenchSet& clean,
                     const dense::DenseStereoOptions& dense_options,
                     const std::vector<int>& points_per_pair) {
  const std::shared_ptr<const dense::SphericalRectifier> grid =
      dense::SharedRectifier(noisy.rig, dense_options.grid);
  const double b = grid->baseline_m(), step = grid->theta_step_rad();
  const MirrorMaskOptions mask_options = dense_options.MaskOptions();
  const std::array<int, 3> windows = {11, 15, 21};
  struct Cell {
    double bound;        // Cramer-Rao median |error| / r
    double within;       // Cramer-Rao share within 1 %
    double noise_error;  // |first-order error of the fit| / r
    bool reported;       // omnirig gives a point at this cell
    bool operator<(const Cell& o) const { return bound < o.bound; }
  };
  std::array<std::vector<Cell>, windows.size()> cells;
  double noise_sum = 0.0;
  const size_t num_pairs = noisy.world_from_rig.size();
  const int rows = grid->rows(), cols = grid->cols();
  const dense::DenseStereo dense(noisy.rig, dense_options);
  for (size_t f = 0; f < num_pairs; ++f) {
    const cv::Mat reported =
        dense.Reconstruct(noisy.images[0][f], noisy.images[1][f]).range_m.t();  // grid layout
    cv::Mat clean_grid[2], noise[2], mask[2];
    double sigma2[2];
    for (int k = 0; k < 2; ++k) {
      const cv::Mat clean_grey = grid->Rectify(ToGreyscale8(clean.images[k][f]), k);
      const cv::Mat noisy_grey = grid->Rectify(ToGreyscale8(noisy.images[k][f]), k);
      mask[k] =
          MirrorMask(clean_grey, Eigen::Vector2d::Zero(), mask_options, grid->ValidMask(k));
      clean_grey.convertTo(clean_grid[k], CV_32F);
      noisy_grey.convertTo(noise[k], CV_32F);
      noise[k] -= clean_grid[k];
      cv::Scalar mean, deviation;
      cv::meanStdDev(noise[k], mean, deviation, mask[k]);
      sigma2[k] = deviation[0] * deviation[0];
      noise_sum += deviation[0] / (2.0 * num_pairs);
    }
    // Each cell's true range and disparity (NaN where the ray misses or a mask holds no cell).
    const Rigid3d& world_from_cam0 = noisy.world_from_rig[f];
    cv::Mat range(rows, cols, CV_64F, cv::Scalar(NAN)), metres_per_cell(rows, cols, CV_64F);
    cv::Mat map_x(rows, cols, CV_32F), map_y(rows, cols, CV_32F);
    cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range_of_rows) {
      for (int r = range_of_rows.start; r < range_of_rows.end; ++r) {
        const double phi = grid->Phi(r);
        for (int c = 0; c < cols; ++c) {
          map_x.at<float>(r, c) = static_cast<float>(c);
          map_y.at<float>(r, c) = static_cast<float>(r);
          if (!mask[0].at<uint8_t>(r, c)) continue;
          const double theta = grid->Theta(c);
          const Eigen::Vector3d ray =
              grid->cam0_from_grid() * Eigen::Vector3d(std::sin(theta) * std::cos(phi),
                                                       std::sin(theta) * std::sin(phi),
                                                       std::cos(theta));
          const double r_m = slam::RangeToSceneSurface(noisy.scene, world_from_cam0.translation,
                                                       world_from_cam0.rotation * ray);
          if (!std::isfinite(r_m)) continue;
          const double parallax =
              std::atan2(r_m * std::sin(theta), r_m * std::cos(theta) - b) - theta;
          const double d = parallax / step;
          if (c - d < 0 || !mask[1].at<uint8_t>(r, static_cast<int>(std::lround(c - d)))) continue;
          range.at<double>(r, c) = r_m;
          metres_per_cell.at<double>(r, c) =
              b * std::sin(theta) / std::pow(std::sin(parallax), 2) * step;
          map_x.at<float>(r, c) = static_cast<float>(c - d);
        }
      }
    });
    cv::Mat dx, noise1_at_match;
    cv::Sobel(clean_grid[0], dx, CV_32F, 1, 0, 1, 0.5);  // as the refinement's gradient
    cv::remap(noise[1], noise1_at_match, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const cv::Mat noise_difference = noise[0] - noise1_at_match;
    for (size_t w = 0; w < windows.size(); ++w) {
      const cv::Size window(windows[w], windows[w]);
      cv::Mat energy, projection;
      cv::boxFilter(dx.mul(dx), energy, CV_32F, window, cv::Point(-1, -1), false);
      cv::boxFilter(dx.mul(noise_difference), projection, CV_32F, window, cv::Point(-1, -1),
                    false);
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          const double r_m = range.at<double>(r, c);
          if (!std::isfinite(r_m)) continue;
          const double e = std::max(1e-9, double{energy.at<float>(r, c)});
          const double per_cell = metres_per_cell.at<double>(r, c) / r_m;
          const double relative_std = std::sqrt((sigma2[0] + sigma2[1]) / e) * per_cell;
          cells[w].push_back({0.674 * relative_std,
                              std::erf(0.01 / (std::sqrt(2.0) * relative_std)),
                              std::abs(projection.at<float>(r, c) / e) * per_cell,
                              reported.at<float>(r, c) > 0.f});
        }
      }
    }
  }
  std::printf("\nthe image noise's share (noise %.2f grey levels on the grid, %zu cells a pair "
              "in both mirrors with a true range):\n",
              noise_sum, cells[0].size() / std::max<size_t>(1, num_pairs));
  for (size_t w = 0; w < windows.size(); ++w) {
    std::sort(cells[w].begin(), cells[w].end());
    for (const int n : points_per_pair) {
      const size_t num = std::min(cells[w].size(), n * num_pairs);
      if (num == 0) continue;
      double within_bound = 0.0, within_noise = 0.0;
      std::vector<double> noise_errors;
      for (size_t i = 0; i < num; ++i) {
        within_bound += cells[w][i].within;
        within_noise += cells[w][i].noise_error <= 0.01 ? 1.0 : 0.0;
        noise_errors.push_back(cells[w][i].noise_error);
      }
      std::nth_element(noise_errors.begin(), noise_errors.begin() + num / 2, noise_errors.end());
      std::printf(
          "  %dx%d window, the %d cells a pair of the lowest bound: Cramer-Rao (white noise) "
          "median |error| >= %.3f %% of range, within 1 %% <= %.1f %%; the noise's own error "
          "in the fit: median %.3f %%, within 1 %% %.1f %%\n",
          windows[w], windows[w], n, 100.0 * cells[w][num / 2].bound, 100.0 * within_bound / num,
          100.0 * noise_errors[num / 2], 100.0 * within_noise / num);
    }
    if (windows[w] != dense_options.refine_window_cells) continue;
    std::vector<double> reported_errors;
    for (const Cell& cell : cells[w]) {
      if (cell.reported) reported_errors.push_back(cell.noise_error);
    }
    if (reported_errors.empty()) continue;
    const size_t num = reported_errors.size();
    const double within = static_cast<double>(std::count_if(
        reported_errors.begin(), reported_errors.end(), [](double e) { return e <= 0.01; }));
    std::nth_element(reported_errors.begin(), reported_errors.begin() + num / 2,
                     reported_errors.end());
    std::printf(
        "  %dx%d window, the %zu cells a pair omnirig reports (with a true range): the noise's "
        "own error in the fit: median %.3f %%, within 1 %% %.1f %%\n",
        windows[w], windows[w], num / std::max<size_t>(1, num_pairs),
        100.0 * reported_errors[num / 2], 100.0 * within / num);
  }
}

// The development room with the held-out set's kind of noise at its own levels and seed: each
// image (noise 1 already) gets Gaussian noise of 1.5, 2.5 or 3.5 grey levels more (by frame and
// camera) and is saved as JPEG at quality 92, 88 or 80 (by frame) and decoded. A development
// set: the std's noise term is calibrated on it.
BenchSet NoisyRoom(const BenchSet& room) {
  BenchSet noisy = room;
  noisy.name = "development room, noisy (+ noise 1.5-3.5, JPEG 80-92)";
  const int qualities[] = {92, 88, 80};
  cv::RNG rng(20261127);
  for (int k = 0; k < 2; ++k) {
    for (size_t f = 0; f < room.images[k].size(); ++f) {
      cv::Mat image;
      room.images[k][f].convertTo(image, CV_32F);
      cv::Mat noise(image.size(), image.type());
      rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.5 + 1.0 * ((f + k) % 3));
      image += noise;
      cv::Mat image8;
      image.convertTo(image8, CV_8U);  // rounds and saturates
      std::vector<uchar> jpeg;
      cv::imencode(".jpg", image8, jpeg, {cv::IMWRITE_JPEG_QUALITY, qualities[f % 3]});
      noisy.images[k][f] = cv::imdecode(jpeg, cv::IMREAD_COLOR);
    }
  }
  return noisy;
}

struct BenchFlags {
  int frames = 4, threads = 2;
  bool with_peer = true, with_job = true;
  bool development_only = false;  // for tuning: the held-out renders are not even made
  bool calibrate_std = false;
  bool job_only = false;
  int job_rounds = 0;  // > 0: only the job against the peer in alternating rounds
  bool merged_rounds = false;  // the rounds' job with the merged cloud (a .tum trajectory)
  bool floor = true;   // the clean lounge as well
};

int Run(const BenchFlags& flags, const dense::DenseStereoOptions& dense_options) {
  cv::setNumThreads(flags.threads);
  std::printf("threads: %d (cv::setNumThreads)\n", flags.threads);
  synth::StereoSequenceOptions options;
  options.num_frames = flags.frames;
  options.render.noise_sigma = 1.0;
  options.seed = 3;
  std::printf("rendering %d pairs of the room at 1024x768...\n", flags.frames);
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  BenchSet development{"development room (engine/synth MakeRoomScene, PNG, noise 1)",
                       false,
                       sequence.scene,
                       sequence.rig,
                       sequence.world_from_rig,
                       sequence.images};
  if (flags.job_rounds > 0) {
    RunJobRounds(sequence, flags.frames, flags.job_rounds, dense_options, flags.merged_rounds);
    return 0;
  }
  if (flags.job_only) {
    RunJob(sequence, flags.frames, dense_options, false);
    RunJob(sequence, flags.frames, dense_options, true);
    return 0;
  }
  const BenchSet noisy_development = NoisyRoom(development);
  if (flags.calibrate_std) {
    dense::DenseStereoOptions raw = dense_options;
    raw.disparity_std_cells = 1e-4;
    raw.disparity_std_scale = 1.0;
    raw.max_relative_range_std = 1e9;  // every point, whatever its std
    std::vector<std::pair<std::string, SubCellBias>> sets;
    for (const BenchSet* set : std::array<const BenchSet*, 2>{&development, &noisy_development}) {
      OmnirigRun run;
      RunOmnirig(*set, raw, false, &run);
      sets.emplace_back(set->name, std::move(run.bias));
    }
    CalibrateStd(sets);
    return 0;
  }
  RunSet(development, flags.with_peer, true, dense_options);
  RunSet(noisy_development, false, false, dense_options);
  PrintNoiseFloor(noisy_development, development, dense_options, {600000, 900000});
  if (flags.development_only) return 0;

  std::printf("\nrendering %d held-out pairs at 1024x768...\n", flags.frames);
  dense::HeldOutSequence lounge = dense::MakeHeldOutLounge(flags.frames);
  BenchSet held_out{lounge.description,      true,
                    std::move(lounge.scene), lounge.rig,
                    lounge.world_from_rig,   std::move(lounge.images)};
  RunSet(held_out, flags.with_peer, false, dense_options);
  if (flags.floor) {
    // What the images hold: the same lounge without sensor noise and JPEG. The rig is the true
    // one in every set here, so no figure of this bench holds a calibration error.
    std::printf("\nrendering %d clean held-out pairs at 1024x768...\n", flags.frames);
    dense::HeldOutSequence clean = dense::MakeHeldOutLounge(flags.frames, 11, true);
    BenchSet clean_set{clean.description,      true,
                       std::move(clean.scene), clean.rig,
                       clean.world_from_rig,   std::move(clean.images)};
    RunSet(clean_set, false, false, dense_options);
    PrintNoiseFloor(held_out, clean_set, dense_options, {600000, 1000000});
  }

  if (flags.with_job) {
    std::printf("\n");
    RunJob(sequence, flags.frames, dense_options, false);
    RunJob(sequence, flags.frames, dense_options, true);
  }
  return 0;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  omnirig::ConfigureAllocator();  // as the omnirig service runs
  omnirig::BenchFlags flags;
  omnirig::dense::DenseStereoOptions options;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--no-peer")) flags.with_peer = false;
    if (!std::strcmp(argv[i], "--no-job")) flags.with_job = false;
    if (!std::strcmp(argv[i], "--job-only")) flags.job_only = true;
    if (!std::strcmp(argv[i], "--merged")) flags.merged_rounds = true;
    if (!std::strcmp(argv[i], "--development-only")) flags.development_only = true;
    if (!std::strcmp(argv[i], "--calibrate-std")) flags.calibrate_std = true;
    if (!std::strcmp(argv[i], "--no-floor")) flags.floor = false;
    if (i + 1 >= argc) continue;
    if (!std::strcmp(argv[i], "--frames"))
      flags.frames = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--job-rounds"))
      flags.job_rounds = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--threads"))
      flags.threads = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--refine-window"))
      options.refine_window_cells = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--block-size"))
      options.block_size = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--sgbm-p1"))
      options.smoothness_p1 = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--sgbm-p2"))
      options.smoothness_p2 = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--step-factor"))
      options.grid.step_factor = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--max-parallax-deg"))
      options.max_parallax_deg = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--disparity-std-cells"))
      options.disparity_std_cells = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--min-confidence"))
      options.min_confidence = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--max-relative-range-std"))
      options.max_relative_range_std = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--disparity-std-scale"))
      options.disparity_std_scale = std::atof(argv[++i]);
  }
  options.Check();
  return omnirig::Run(flags, options);
}
