#include "engine/dense/pipeline.h"

#include <atomic>
#include <deque>
#include <future>
#include <memory>
#include <stdexcept>
#include <utility>

#include <opencv2/imgcodecs.hpp>

#include "engine/dense/dense_map.h"
#include "engine/dense/range_io.h"
#include "engine/features/image.h"
#include "engine/geometry/ply.h"
#include "engine/util/background_task.h"
#include "engine/util/check.h"
#include "engine/util/error_prefix.h"
#include "engine/util/progress_range.h"

namespace omnirig::dense {
namespace {

cv::Mat ReadImage(const ImageReader& read, const std::string& name, int imread_flags) {
  const cv::Mat image = read(name, imread_flags);
  OMNIRIG_CHECK(!image.empty(), "cannot read image '" << name << "'");
  return image;
}

ProgressSink PairRange(const ProgressSink& progress, size_t k, size_t num_pairs) {
  return SubRange(progress, static_cast<double>(k) / num_pairs,
                  static_cast<double>(k + 1) / num_pairs);
}

// Where the pairs' clouds go (see pipeline.h).
class CloudOutputs {
 public:
  CloudOutputs(const std::filesystem::path& dir, size_t num_pairs,
               std::optional<PairPlacement> placement)
      : dir_(dir),
        num_pairs_(num_pairs),
        placement_(std::move(placement)),
        merged_(dir / "cloud.ply") {}

  // Pair k's cloud file and placement in `outcome`, on the calling thread.
  void Describe(size_t k, const std::string& pair_name, StereoPairOutcome* outcome) {
    if (num_pairs_ == 1 && !placement_) return;
    outcome->cloud_file = CloudFileName(pair_name);
    if (k == 0) first_cloud_file_ = outcome->cloud_file;
    if (!placement_) return;
    const bool placed = placement_->world_from_cam0[k].has_value();
    outcome->placed = placed;
    num_placed_ += placed;
  }

  // Writes pair k's cloud, and appends it to the merged cloud when it is placed. Dense runs
  // call it on their writer thread (one pair at a time, in pair order) while the next pair is
  // matched; Finish() only once the last Write() has returned.
  void Write(size_t k, const std::string& pair_name, const PlyCloud& cloud) {
    if (num_pairs_ == 1 && !placement_) {
      WritePly(dir_ / "cloud.ply", cloud);
      return;
    }
    WritePly(dir_ / CloudFileName(pair_name), cloud);
    if (!placement_ || !placement_->world_from_cam0[k]) return;
    const Rigid3d& world_from_cam0 = *placement_->world_from_cam0[k];
    if (cloud.has_range_std) {  // dense: fused into one surface (dense_map.h)
      fused_.Add(world_from_cam0, cloud);
      return;
    }
    PlyCloud in_world = cloud;
    in_world.comment = "omnirig stereo_reconstruct: all placed pairs in the world of " +
                       placement_->source + ", metres";
    for (Eigen::Vector3f& p : in_world.positions) {
      p = (world_from_cam0 * p.cast<double>()).cast<float>();
    }
    merged_.Append(in_world);
  }

  void Finish(StereoPairsReport* report) {
    if (placement_) {
      StereoPairsReport::Trajectory trajectory{placement_->source, num_placed_,
                                               placement_->warning};
      if (num_placed_ < static_cast<int>(num_pairs_) && trajectory.warning.empty()) {
        trajectory.warning = std::to_string(num_pairs_ - num_placed_) +
                             " pair(s) have no pose in the trajectory and are not in cloud.ply";
      }
      report->trajectory = trajectory;
    }
    if (num_placed_ > 0 && fused_.num_frames() > 0) {
      const PlyCloud fused =
          fused_.Cloud("omnirig stereo_reconstruct: all placed pairs fused in the world of " +
                       placement_->source + ", metres");
      WritePly(dir_ / "cloud.ply", fused);
      report->merged_points_per_m2 = PointsPerSquareMetre(fused.positions);
      report->artifact = "cloud.ply";
      report->clouds_merged = true;
    } else if (num_placed_ > 0) {
      merged_.Finish();
      report->artifact = "cloud.ply";
      report->clouds_merged = true;
    } else if (num_pairs_ == 1) {
      report->artifact = "cloud.ply";
    } else if (num_pairs_ > 1) {
      report->artifact = first_cloud_file_;
      report->clouds_merged = false;
    }
  }

 private:
  std::filesystem::path dir_;
  size_t num_pairs_;
  std::optional<PairPlacement> placement_;
  PlyAppender merged_;                    // sparse pairs, appended
  DenseMap fused_{MergedCloudOptions()};  // dense pairs, fused
  int num_placed_ = 0;
  std::string first_cloud_file_;
};

size_t RunSparse(const StereoRig& rig, const ImageReader& read,
                 const std::vector<ImagePairNames>& pairs, const StereoReconstructOptions& options,
                 const std::function<void(const StereoPairOutcome&)>& on_pair,
                 const ProgressSink& progress, CloudOutputs* outputs) {
  size_t num_points = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    progress.ThrowIfCancelled();
    const cv::Mat image0 = ReadImage(read, pairs[k].cam0, cv::IMREAD_COLOR);
    const cv::Mat image1 = ReadImage(read, pairs[k].cam1, cv::IMREAD_COLOR);
    const StereoPairReport report = WithErrorPrefix("pair '" + pairs[k].name + "': ", [&] {
      return ReconstructStereoPair(rig, image0, image1, options,
                                   PairRange(progress, k, pairs.size()));
    });
    StereoPairOutcome outcome;
    outcome.index = k;
    outcome.names = &pairs[k];
    outcome.sparse = &report;
    outputs->Describe(k, pairs[k].name, &outcome);
    outputs->Write(k, pairs[k].name, SparseCloud(report.points));
    if (on_pair) on_pair(outcome);
    num_points += report.points.size();
  }
  return num_points;
}

// Writes pair `name`'s panoramas and cloud (on RunDense's writer thread). An error names the
// pair, as the matching's do.
void WriteDensePair(size_t k, const std::string& name, const DensePairResult& pair_result,
                    const std::filesystem::path& dir, CloudOutputs* outputs) {
  try {
    const std::string base = RangeBaseName(name);
    WriteRangeTiff(dir / (base + "_range.tiff"), pair_result.range_m);
    WriteRangePng(dir / (base + "_range.png"), pair_result.range_m);
    outputs->Write(
        k, name,
        ToPlyCloud(pair_result.points,
                   "omnirig stereo_reconstruct (dense): points in cam0's frame, metres"));
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("pair '" + name + "': " + e.what());
  } catch (const std::exception& e) {
    throw std::runtime_error("pair '" + name + "': " + e.what());
  }
}

// Pairs matched at once, each on a thread of its own. One pair's matching leaves a core idle
// in its serial stretches and beside its file writing; two pairs at once fill them (OpenCV runs
// a parallel loop that starts while another one runs serially, so the two pairs share the
// cores rather than oversubscribe them). Measured with bench_dense --job-rounds: docs/dense.md
// (9 % less time a pair; a job that fuses its pairs, bound by the fusion on the writer thread,
// a few per cent more).
constexpr size_t kPairsInFlight = 2;

// The pairs are read and matched kPairsInFlight at a time; their outcomes and files follow in
// pair order, written on a background thread while the next pairs are matched.
size_t RunDense(const StereoRig& rig, const ImageReader& read,
                const std::vector<ImagePairNames>& pairs, const StereoPairsOptions& options,
                const std::filesystem::path& output_dir,
                const std::function<void(const StereoPairOutcome&)>& on_pair,
                const ProgressSink& progress, CloudOutputs* outputs,
                StereoPairsReport::Grid* grid) {
  progress.Report(0.0, "rectify", "building the rectification tables");
  const DenseStereo dense(rig, options.dense, options.rectification_tables_dir);
  // Only the oldest pair in flight reports its progress, so that the job's fraction only grows.
  std::atomic<size_t> front{0};
  // A job of one pair is matched on this thread, its two images decoded at once (on a thread
  // of its own, a process's first one-pair job took twice as long: docs/dense.md).
  const bool one_pair = pairs.size() == 1;
  const auto match_pair = [&](size_t k) {
    progress.ThrowIfCancelled();
    // Only cam0's colours make the points' colours: cam1 is read as grey (a JPEG's luma alone).
    std::future<cv::Mat> read_image1 = std::async(
        one_pair ? std::launch::async : std::launch::deferred,
        [&] { return ReadImage(read, pairs[k].cam1, cv::IMREAD_GRAYSCALE); });
    const cv::Mat image0 = ReadImage(read, pairs[k].cam0, cv::IMREAD_COLOR);
    const cv::Mat image1 = read_image1.get();
    const ProgressSink range = PairRange(progress, k, pairs.size());
    ProgressSink pair_progress;
    pair_progress.report = [&front, k, range](double fraction, const std::string& stage,
                                              const std::string& message) {
      if (front.load() == k) range.Report(fraction, stage, message);
    };
    pair_progress.is_cancelled = progress.is_cancelled;
    return std::make_shared<DensePairResult>(WithErrorPrefix(
        "pair '" + pairs[k].name + "': ",
        [&] { return dense.Reconstruct(image0, image1, pair_progress); }));
  };
  // Declared before the pairs in flight: an error unwinds them (each waits for its pair) before
  // the writer (which waits for its task).
  BackgroundTask writer;
  std::deque<std::future<std::shared_ptr<DensePairResult>>> in_flight;
  size_t next = 0;
  const auto launch = [&] {
    while (next < pairs.size() && in_flight.size() < kPairsInFlight) {
      in_flight.push_back(std::async(one_pair ? std::launch::deferred : std::launch::async,
                                     match_pair, next++));
    }
  };
  launch();
  size_t num_points = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const std::shared_ptr<DensePairResult> pair_result = in_flight.front().get();
    in_flight.pop_front();
    front = k + 1;
    launch();
    StereoPairOutcome outcome;
    outcome.index = k;
    outcome.names = &pairs[k];
    outcome.dense = pair_result.get();
    const std::string base = RangeBaseName(pairs[k].name);
    outcome.range_tiff = base + "_range.tiff";
    outcome.range_png = base + "_range.png";
    outputs->Describe(k, pairs[k].name, &outcome);
    num_points += pair_result->points.size();
    // on_pair (the pair's figures, e.g. the medians of its ranges) runs with the writing, so
    // that this thread goes back to wait for the next pair at once.
    writer.Run([k, outcome, pair_result, &output_dir, outputs, &on_pair] {
      if (on_pair) on_pair(outcome);
      WriteDensePair(k, outcome.names->name, *pair_result, output_dir, outputs);
    });
  }
  writer.Wait();
  *grid = {dense.rectifier().rows(), dense.rectifier().cols(), dense.rectifier().theta_step_rad(),
           dense.num_disparities()};
  return num_points;
}

}  // namespace

void StereoPairsOptions::Check() const {
  if (use_dense) {
    dense.Check();
  } else {
    sparse.Check();
  }
}

std::string CloudFileName(const std::string& pair_name) {
  std::string out = "cloud_";
  for (char c : pair_name) out += (c == '/' || c == '.' || c == '\\') ? '_' : c;
  return out + ".ply";
}

std::string RangeBaseName(const std::string& pair_name) {
  std::string out = std::filesystem::path(pair_name).replace_extension().string();
  for (char& c : out) {
    if (c == '/' || c == '\\') c = '_';
  }
  return out;
}

StereoPairsReport ReconstructStereoPairs(
    const StereoRig& rig, const std::filesystem::path& dataset_dir,
    const std::vector<ImagePairNames>& pairs, const std::optional<PairPlacement>& placement,
    const StereoPairsOptions& options, const std::filesystem::path& output_dir,
    const std::function<void(const StereoPairOutcome&)>& on_pair, const ProgressSink& progress) {
  return ReconstructStereoPairs(rig, FolderImageReader(dataset_dir), pairs, placement, options,
                                output_dir, on_pair, progress);
}

StereoPairsReport ReconstructStereoPairs(
    const StereoRig& rig, const ImageReader& read,
    const std::vector<ImagePairNames>& pairs, const std::optional<PairPlacement>& placement,
    const StereoPairsOptions& options, const std::filesystem::path& output_dir,
    const std::function<void(const StereoPairOutcome&)>& on_pair, const ProgressSink& progress) {
  options.Check();
  OMNIRIG_CHECK(!placement || placement->world_from_cam0.size() == pairs.size(),
                "the placement holds " << placement->world_from_cam0.size() << " poses for "
                                       << pairs.size() << " pairs");
  StereoPairsReport report;
  CloudOutputs outputs(output_dir, pairs.size(), placement);
  if (options.use_dense) {
    StereoPairsReport::Grid grid;
    report.num_points =
        RunDense(rig, read, pairs, options, output_dir, on_pair, progress, &outputs, &grid);
    report.grid = grid;
  } else {
    report.num_points =
        RunSparse(rig, read, pairs, options.sparse, on_pair, progress, &outputs);
  }
  outputs.Finish(&report);
  progress.Report(1.0, "done",
                  std::to_string(report.num_points) + " points from " +
                      std::to_string(pairs.size()) + " pair(s)");
  return report;
}

}  // namespace omnirig::dense
