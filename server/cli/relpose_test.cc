// `omnirig relpose` end to end on a small synthetic dataset (label integration): the result
// JSON lands where `-o` (the shared parser's one-letter option) or `--output` says.

#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"
#include "server/cli/commands.h"
#include "testing/synth/calib_board.h"

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class RelposeCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    synth::StereoBoardOptions options = synth::QuickStereoBoardOptions(6, 3);
    set_ = new synth::StereoBoardSet(synth::MakeStereoBoardSet(options));
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("omnirig_relpose_cli_" + std::to_string(std::random_device()())));
    for (int c = 0; c < 2; ++c) {
      const fs::path camera_dir = *dir_ / "data" / ("cam" + std::to_string(c));
      fs::create_directories(camera_dir);
      for (size_t i = 0; i < set_->names.size(); ++i) {
        cv::imwrite((camera_dir / (set_->names[i] + ".png")).string(), set_->images[c][i]);
      }
      std::ofstream calib(*dir_ / ("calib" + std::to_string(c) + ".json"));
      calib << json{{"camera", api::CameraToJson(c == 0 ? set_->rig.cam0 : set_->rig.cam1)}};
    }
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete set_;
  }

  // The command line up to the output option, with the rendered cameras as calibrations.
  static Args BaseArgs() {
    return {"--cols",
            std::to_string(set_->board.cols),
            "--rows",
            std::to_string(set_->board.rows),
            "--square-mm",
            std::to_string(set_->board.square_size_m * 1e3),
            "--calib0",
            (*dir_ / "calib0.json").string(),
            "--calib1",
            (*dir_ / "calib1.json").string(),
            (*dir_ / "data").string()};
  }

  static json ReadJson(const fs::path& path) {
    std::ifstream in(path);
    EXPECT_TRUE(in.good()) << path;
    json document;
    in >> document;
    return document;
  }

  static synth::StereoBoardSet* set_;
  static fs::path* dir_;
};

synth::StereoBoardSet* RelposeCli::set_ = nullptr;
fs::path* RelposeCli::dir_ = nullptr;

TEST_F(RelposeCli, DashOWritesTheResult) {
  const fs::path out = *dir_ / "rig_short.json";
  Args args = BaseArgs();
  args.insert(args.end(), {"-o", out.string()});
  ASSERT_EQ(RunRelpose(args), 0);
  const json result = ReadJson(out);
  const double truth = set_->rig.cam0_from_cam1.translation.norm();
  EXPECT_NEAR(result.at("baseline_m").get<double>(), truth, 1e-3 * truth);
  EXPECT_EQ(result.at("pairs").size(), set_->names.size());
}

TEST_F(RelposeCli, LongOutputOptionWritesTheSameResult) {
  const fs::path out_short = *dir_ / "rig_a.json";
  const fs::path out_long = *dir_ / "rig_b.json";
  Args short_args = BaseArgs();
  short_args.insert(short_args.end(), {"-o", out_short.string()});
  Args long_args = BaseArgs();
  long_args.insert(long_args.end(), {"--output", out_long.string()});
  ASSERT_EQ(RunRelpose(short_args), 0);
  ASSERT_EQ(RunRelpose(long_args), 0);
  EXPECT_EQ(ReadJson(out_short).at("baseline_m"), ReadJson(out_long).at("baseline_m"));
}

// --intrinsics-model names a model; with given calibrations "free" refines them, and "auto"
// chooses between keeping them ("fixed") and "free".
TEST_F(RelposeCli, IntrinsicsModelOptionReachesTheJob) {
  const fs::path out = *dir_ / "rig_free.json";
  Args args = BaseArgs();
  args.insert(args.end(), {"--intrinsics-model", "free", "-o", out.string()});
  ASSERT_EQ(RunRelpose(args), 0);
  const json result = ReadJson(out);
  EXPECT_TRUE(result.at("intrinsics_refined").get<bool>());
  EXPECT_EQ(result.at("intrinsics_model").at("chosen"), "free");
  EXPECT_EQ(result.at("intrinsics_model").at("selection"), "given");
  const fs::path automatic_out = *dir_ / "rig_auto.json";
  Args automatic = BaseArgs();
  automatic.insert(automatic.end(), {"--intrinsics-model", "auto", "-o", automatic_out.string()});
  ASSERT_EQ(RunRelpose(automatic), 0);
  const std::string chosen = ReadJson(automatic_out).at("intrinsics_model").at("chosen");
  EXPECT_TRUE(chosen == "fixed" || chosen == "free") << chosen;
  // The per-camera models are names the option takes (they too need the job's calibrations);
  // a name it does not know is refused with the list of those it does.
  for (const std::string model : {"tangential_free_cam1", "best"}) {
    Args named = BaseArgs();
    named.insert(named.end(), {"--intrinsics-model", model});
    try {
      RunRelpose(named);
      ADD_FAILURE() << model << " with given calibrations was accepted";
    } catch (const InvalidArgument& e) {
      const std::string expected =
          model == "best" ? "tangential_free_cam0, tangential_free_cam1" : "calibrate the cameras";
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

TEST_F(RelposeCli, BothOutputSpellingsOrAnUnknownLetterAreRefused) {
  Args both = BaseArgs();
  both.insert(both.end(),
              {"-o", (*dir_ / "x.json").string(), "--output", (*dir_ / "y.json").string()});
  EXPECT_THROW(RunRelpose(both), InvalidArgument);
  EXPECT_FALSE(fs::exists(*dir_ / "x.json"));
  Args unknown = BaseArgs();
  unknown.insert(unknown.end(), {"-q", "1"});
  EXPECT_EQ(RunRelpose(unknown), 2);
}

}  // namespace
}  // namespace omnirig::cli
