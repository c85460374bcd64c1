// `omnirig relpose`: the metric pose between a stereo rig's two cameras from image pairs of a
// shared board, the same engine call as the `relative_pose` job type.
//
//   omnirig relpose --board checkerboard --cols 9 --rows 6 --square-mm 24.23
//       [--calib0 c0.json --calib1 c1.json] DIR -o rig.json
//
// DIR holds cam0/NAME and cam1/NAME images, paired by NAME. --calib0/--calib1 take the JSON of
// `omnirig calibrate` (or a bare camera object); without them each camera is calibrated from
// its own images first.

#include <iomanip>
#include <iostream>

#include <nlohmann/json.hpp>

#include "api/relpose_job.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"
#include "server/cli/files.h"
#include "server/cli/job_options.h"

namespace omnirig::cli {
namespace {

using nlohmann::json;

// A calibration file as a job result: `omnirig calibrate`'s JSON has "camera"; a bare camera
// object is wrapped.
json LoadCalibrationFile(const std::string& path) {
  json document = ReadJsonFile(path, "calibration file");
  if (document.is_object() && document.contains("model") && !document.contains("camera")) {
    return {{"camera", document}};
  }
  return document;
}

void PrintStageProgress(double fraction, const std::string& stage, const std::string& message) {
  // Per-iteration and per-fold lines are noise here.
  if (stage == "refine" || stage == "solve" || stage == "cross_validation") return;
  PrintProgress(fraction, stage, message);
}

void PrintSummary(const json& result) {
  std::cerr << std::fixed << std::setprecision(3) << "baseline "
            << result["baseline_m"].get<double>() * 1e3 << " mm +- "
            << result["baseline_std_m"].get<double>() * 1e3 << " mm, rotation std "
            << std::setprecision(4) << result["rotation_std_deg"].get<double>() << " deg, RMS "
            << std::setprecision(3) << result["rms_px"].get<double>() << " px, "
            << result["num_pairs_used"].get<int>() << " of " << result["pairs"].size()
            << " pairs used\n";
  if (result.contains("intrinsics_model") && result["intrinsics_model"].contains("candidates")) {
    std::cerr << "intrinsics model " << result["intrinsics_model"]["chosen"].get<std::string>()
              << " (" << result["intrinsics_model"]["rule"].get<std::string>() << ")\n";
    for (const json& candidate : result["intrinsics_model"]["candidates"]) {
      std::cerr << "  " << candidate["name"].get<std::string>() << ": baseline "
                << candidate["baseline_m"].get<double>() * 1e3 << " mm, held-out RMS "
                << candidate["cv_rms_px"].dump() << " px\n";
    }
  }
  for (const json& pair : result["pairs"]) {
    if (!pair["used"].get<bool>()) {
      std::cerr << "  unused " << pair["name"].get<std::string>() << ": "
                << pair["reason"].get<std::string>() << "\n";
    }
  }
}

void DeclareOptions(ArgParser* parser) {
  AddBoardOptions({"", "", "", "", ""}, parser);
  parser->AddOption("calib0", "", "cam0's calibration JSON (omnirig calibrate -o); with --calib1");
  parser->AddOption("calib1", "",
                    "cam1's calibration JSON; without both, each camera is "
                    "calibrated from its own images first");
  parser->AddOption("intrinsics-model", "auto",
                    "auto, fixed, tangential_fixed, tangential_free_cam0, tangential_free_cam1 "
                    "or free: which intrinsics the joint refinement frees (auto: chosen by "
                    "leave-one-pair-out cross-validation)");
  parser->AddOption("threads", "1", "solver threads");
  parser->AddOption("o", "", "write the result JSON here (also --output); default: stdout");
  parser->AddOption("output", "", "the same as -o");
  parser->SetPositional("DIR", "folder holding cam0/NAME and cam1/NAME images, paired by NAME");
}

json ParamsFromArgs(const ArgParser& parser) {
  OMNIRIG_CHECK(parser.Has("cols") && parser.Has("rows") && parser.Has("square-mm"),
                "--cols, --rows and --square-mm are required");
  OMNIRIG_CHECK(parser.Has("calib0") == parser.Has("calib1"),
                "give both --calib0 and --calib1, or neither");
  json params = {{"board", BoardParams(parser)}};
  if (parser.Has("calib0")) {
    params["calibrations"] = {{"cam0", parser.Get("calib0")}, {"cam1", parser.Get("calib1")}};
  }
  if (parser.Has("intrinsics-model")) params["intrinsics_model"] = parser.Get("intrinsics-model");
  return params;
}

}  // namespace

int RunRelpose(const Args& args) {
  ArgParser parser("relpose",
                   "Measures the metric pose between a stereo rig's two cameras (cam0_from_cam1) "
                   "from image pairs in which both see the same board.");
  DeclareOptions(&parser);
  if (!parser.Parse(args)) return parser.exit_code();
  OMNIRIG_CHECK(parser.positional().size() == 1, "expected exactly one DIR (see --help)");
  OMNIRIG_CHECK(!(parser.Has("o") && parser.Has("output")), "give -o or --output, not both");
  const std::string output = parser.Has("o") ? parser.Get("o") : parser.Get("output");
  const json params = ParamsFromArgs(parser);

  api::JobContext context = LocalJobContext(parser.positional()[0], parser.GetInt("threads"));
  context.progress.report = PrintStageProgress;
  context.load_result = LoadCalibrationFile;  // the "job ids" are file paths here
  const json result = api::RunRelativePoseJob(params, context);
  PrintSummary(result);
  if (output.empty()) {
    std::cout << result.dump(2) << "\n";
    return 0;
  }
  WriteFile(output, result.dump(2) + "\n");
  std::cerr << "wrote " << output << "\n";
  return 0;
}

}  // namespace omnirig::cli
