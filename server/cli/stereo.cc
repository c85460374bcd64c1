// `omnirig stereo`: 3D from stereo pairs of a calibrated rig, the same engine call as the
// `stereo_reconstruct` job type (api/stereo_job.h).
//
//   omnirig stereo --rig rig.json DIR -o OUTDIR [--method dense|sparse] [--options opts.json]
//       [--threads N] [--cache-dir CACHE|none]
//
// rig.json is a relative_pose result (cam0_from_cam1 and both cameras); DIR holds cam0/NAME and
// cam1/NAME images, paired by NAME. OUTDIR receives cloud.ply, per pair (dense)
// NAME_range.tiff and NAME_range.png, cloud_NAME.ply with more than one pair, and result.json
// (the job's result). opts.json holds the job's params other than "rig" and "method". The rig's
// rectification tables are kept in CACHE/rectification (by default OUTDIR/../.omnirig-cache),
// so a later run of the rig reads them instead of building them.

#include <filesystem>
#include <fstream>
#include <iostream>

#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>

#include "api/stereo_job.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"
#include "server/cli/files.h"
#include "server/cli/job_options.h"

namespace omnirig::cli {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

void PrintResult(const json& result, const fs::path& out_dir) {
  std::cout << result["method"].get<std::string>() << ": " << result["num_points"] << " points in "
            << result["pairs"].size() << " pairs\n";
  for (const json& pair : result["pairs"]) {
    std::cout << "  " << pair["name"].get<std::string>() << ": " << pair["num_points"]
              << " points, median range " << pair["median_range_m"] << " m"
              << (pair.contains("warning") ? " (" + pair["warning"].get<std::string>() + ")" : "")
              << "\n";
  }
  if (result.contains("artifact")) {
    std::cout << "wrote " << (out_dir / result["artifact"].get<std::string>()).string()
              << (result.value("clouds_merged", true) ? "" : " (one of the pairs' clouds)")
              << ", result.json\n";
  }
}

}  // namespace

int RunStereo(const Args& raw_args) {
  ArgParser args("stereo",
                 "3D from stereo pairs of a calibrated rig: dense range panoramas and clouds "
                 "(default), or sparse SIFT points.");
  args.AddOption("rig", "", "relative_pose result JSON (cam0_from_cam1 and both cameras)");
  args.AddOption("method", "dense", "dense or sparse");
  args.AddOption("o", "stereo_out", "output folder");
  args.AddOption("options", "", "JSON file with the job's params other than rig and method");
  args.AddOption("threads", "2", "threads for the dense matcher");
  AddCacheDirOption(&args);
  args.SetPositional("DIR",
                     "folder with cam0/ and cam1/ images, paired by name (a .tum "
                     "trajectory in it places the pairs into one merged cloud.ply)");
  if (!args.Parse(raw_args)) return args.exit_code();
  OMNIRIG_CHECK(args.positional().size() == 1, "expected one DIR (see --help)");
  OMNIRIG_CHECK(args.Has("rig"), "--rig is required (a relative_pose result JSON)");
  const int threads = args.GetInt("threads");
  OMNIRIG_CHECK(threads >= 1, "--threads must be at least 1");
  json params =
      args.Has("options") ? ReadJsonFile(args.Get("options"), "--options") : json::object();
  OMNIRIG_CHECK(params.is_object(), "--options: expected a JSON object");
  params["rig"] = args.Get("rig");
  params["method"] = args.Get("method");

  const fs::path out_dir = args.Get("o");
  fs::create_directories(out_dir);
  api::JobContext context = LocalJobContext(args.positional()[0], threads);
  for (const fs::directory_entry& entry : fs::directory_iterator(context.dataset_dir)) {
    if (entry.path().extension() == ".tum") {
      context.image_names.push_back(entry.path().filename().string());
    }
  }
  context.output_dir = out_dir;
  context.cache_dir = CacheDirFromArgs(args, out_dir);
  const std::string rig_path = args.Get("rig");
  context.load_result = [&](const std::string&) { return ReadJsonFile(rig_path, "--rig"); };
  cv::setNumThreads(threads);
  const json result = api::RunStereoReconstructJob(params, context);
  WriteFile((out_dir / "result.json").string(), result.dump(2) + "\n");
  PrintResult(result, out_dir);
  return 0;
}

}  // namespace omnirig::cli
