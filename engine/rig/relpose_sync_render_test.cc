// The synchronisation test's false alarms on the renderer's synchronised pairs (label
// integration: 6 rendered rigs, about 4 CPU minutes). The test promises that a set of
// simultaneous pairs loses one or more in at most sync_false_alarm_rate (1 %) of rigs
// (relpose_sync.h). Before each pair was judged by its own corner noise (the F form of the
// statistic), 6 of 20 rig tests on such renders lost a pair (docs/relpose.md).

#include <array>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/rig/relative_pose.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

constexpr int kNumSeeds = 6;
constexpr int kNumPairs = 20;

CameraModel CalibrateFromPairs(const std::vector<StereoBoardPair>& pairs, int camera,
                               const CameraModel& size_of, const BoardSpec& board) {
  std::vector<CalibrationView> views;
  for (const StereoBoardPair& pair : pairs) {
    views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
  }
  return Calibrate(views, size_of.width, size_of.height, board, CalibrationOptions(),
                   ProgressSink())
      .camera;
}

bool LeftOutAsUnsynchronised(const RelativePosePairReport& pair) {
  return pair.reason.find("exposures not simultaneous?") != std::string::npos;
}

// What the rigs of one seed add to the counts.
struct Counts {
  int rigs = 0, rigs_losing = 0;                 // the test as the job runs it
  int pairs = 0, over_limit = 0, p_under_1 = 0;  // first round, nothing left out
  int moved = 0, moved_found = 0;
};

// One seed: 20 synchronised pairs, each camera calibrated from its own 20 images, the rig with
// the cameras kept at those calibrations and with the intrinsics refined; then the same pairs
// with the board of two of them moved by 2 mm between the exposures.
void RunSeed(uint64_t seed, std::array<Counts, 2>* counts_by_setting) {
  const synth::StereoBoardSet set =
      synth::MakeStereoBoardSet(synth::QuickStereoBoardOptions(kNumPairs, seed));
  const BoardSpec board = ToBoardSpec(set.board);
  std::vector<StereoBoardPair> pairs;
  for (size_t i = 0; i < set.names.size(); ++i) {
    pairs.push_back({set.names[i], DetectBoard(set.images[0][i], board, DetectOptions()),
                     DetectBoard(set.images[1][i], board, DetectOptions())});
  }
  const CameraModel cam0 = CalibrateFromPairs(pairs, 0, set.rig.cam0, board);
  const CameraModel cam1 = CalibrateFromPairs(pairs, 1, set.rig.cam1, board);
  std::vector<StereoBoardPair> moved = pairs;
  std::mt19937 rng(static_cast<uint32_t>(seed));
  std::normal_distribution<double> normal(0.0, 1.0);
  for (size_t i : {5, 14}) {
    const Eigen::Vector3d direction(normal(rng), normal(rng), normal(rng));
    MoveBoardBeforeCam1(set, i, 0.002 * direction.normalized(), &moved[i].cam1);
  }
  for (const bool refine : {false, true}) {
    Counts* counts = &(*counts_by_setting)[refine ? 1 : 0];
    RelativePoseOptions options;
    options.refine_intrinsics = refine;
    const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, pairs, options);
    ASSERT_TRUE(report.success) << report.message;
    ++counts->rigs;
    int lost = 0;
    for (const RelativePosePairReport& pair : report.pairs) {
      if (!LeftOutAsUnsynchronised(pair)) continue;
      ++lost;
      std::printf("seed %d refine %d: %s\n", static_cast<int>(seed), refine, pair.reason.c_str());
    }
    counts->rigs_losing += lost > 0 ? 1 : 0;
    // The first round alone (the limit out of reach: the statistics do not depend on it).
    RelativePoseOptions first_round = options;
    first_round.sync_test.false_alarm_rate = 1e-12;
    const SyncTestReport first =
        EstimateRelativePose(cam0, cam1, board, pairs, first_round).sync_test;
    ASSERT_TRUE(first.run);
    // The limit the job uses for this many pairs (1 % family-wise).
    const double first_limit = ChiSquareUpperQuantile(
        options.sync_test.false_alarm_rate / static_cast<double>(first.pairs.size()), 6);
    for (const PairSyncStatistic& pair : first.pairs) {
      if (!pair.valid) continue;
      ++counts->pairs;
      counts->over_limit += pair.statistic > first_limit ? 1 : 0;
      counts->p_under_1 += SyncStatisticSurvival(pair.statistic) < 0.01 ? 1 : 0;
    }
    const RelativePoseReport moved_report = EstimateRelativePose(cam0, cam1, board, moved, options);
    ASSERT_TRUE(moved_report.success) << moved_report.message;
    for (size_t i : {5, 14}) {
      if (!moved[i].cam0.found || !moved[i].cam1.found) continue;
      ++counts->moved;
      counts->moved_found += LeftOutAsUnsynchronised(moved_report.pairs[i]) ? 1 : 0;
    }
  }
}

// 6 rigs of 20 pairs per intrinsics setting. With the intrinsics refined with the rig (every
// model of the job's "auto" but "fixed"): at the promised 1 % per rig, two or more of 6 rigs
// losing a pair has probability 0.15 %; at the limit's per-pair level (0.05 %), two or more of
// 120 pairs over it 0.2 %. Both settings, 240 pairs: eight or more with p < 1 % has probability
// 0.3 % (the rule before this test lost a pair in 7 of 31 such rig tests, 4.5 % and 2.5 % of
// the pairs under 1 %). The same for the cameras kept at their own calibrations since the test
// expects the held-out rigs' error at each pair (before, 2 of 16 rigs lost a pair in
// bench_relpose --only sync: docs/relpose.md). Boards moved by 2 mm between the exposures are
// found in every rig.
TEST(PairSynchronisationRenders, FalseAlarmsMatchTheStatedRate) {
  std::array<Counts, 2> counts;  // cameras kept, intrinsics refined
  for (int s = 0; s < kNumSeeds; ++s) {
    RunSeed(4000 + s, &counts);
    if (HasFatalFailure()) return;
  }
  for (int refine = 0; refine < 2; ++refine) {
    const Counts& c = counts[refine];
    std::printf(
        "synchronised renders, intrinsics %s: %d of %d rigs lost a pair; first round: %d "
        "of %d pairs over the limit, %d with p < 1 %%; boards moved by 2 mm found: %d of "
        "%d\n",
        refine ? "refined" : "kept", c.rigs_losing, c.rigs, c.over_limit, c.pairs, c.p_under_1,
        c.moved_found, c.moved);
    EXPECT_GE(c.pairs, 110);
    EXPECT_EQ(c.moved_found, c.moved);
    EXPECT_GE(c.moved, 10);
  }
  for (const Counts& c : counts) {
    EXPECT_LE(c.rigs_losing, 1);
    EXPECT_LE(c.over_limit, 1);
  }
  EXPECT_LE(counts[0].p_under_1 + counts[1].p_under_1, 7);
}

}  // namespace
}  // namespace omnirig
