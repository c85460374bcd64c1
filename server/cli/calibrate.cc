// `omnirig calibrate`: calibrates one catadioptric camera from images of a board, the same
// engine call and the same result JSON as the `calibration` job type.
//
//   omnirig calibrate --board checkerboard --cols 8 --rows 6 --square-mm 40 IMAGES...
//       -o calib.json [--export-opencv FILE] [--export-kalibr FILE] [--fix xi,skew]
//       [--free k5] [--hint "IMAGE:u,v,u,v,u,v,u,v;IMAGE2:..."] [--hints FILE.json]
//       [--overlays DIR] [--threads N]
//       [--svp] [--rim-radius-mm R --rim-height-mm H] [--svp-image IMAGE]

#include <iomanip>
#include <iostream>

#include <nlohmann/json.hpp>

#include "api/calibration_job.h"
#include "engine/calib/model_io.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"
#include "server/cli/files.h"
#include "server/cli/job_options.h"

namespace omnirig::cli {
namespace {

using nlohmann::json;

// "IMAGE:u,v,u,v,u,v,u,v" entries separated by ';' -> the API's "hints" object.
void AddHints(const std::string& text, json* hints) {
  for (const std::string& entry : SplitList(text, ';')) {
    const size_t colon = entry.rfind(':');
    OMNIRIG_CHECK(colon != std::string::npos && colon > 0,
                  "--hint: expected IMAGE:u,v,u,v,u,v,u,v, got '" << entry << "'");
    const std::vector<std::string> numbers = SplitList(entry.substr(colon + 1), ',');
    OMNIRIG_CHECK(numbers.size() == 8,
                  "--hint: expected 8 numbers for '" << entry.substr(0, colon) << "'");
    json corners = json::array();
    for (int i = 0; i < 4; ++i) {
      try {
        corners.push_back({std::stod(numbers[2 * i]), std::stod(numbers[2 * i + 1])});
      } catch (const std::exception&) {
        OMNIRIG_CHECK(false, "--hint: '" << entry << "' holds a non-number");
      }
    }
    (*hints)[entry.substr(0, colon)] = corners;
  }
}

json ParamsFromArgs(const ArgParser& args) {
  json options = json::object();
  if (args.Has("fix")) options["fix"] = SplitList(args.Get("fix"), ',');
  if (args.Has("free")) options["free"] = SplitList(args.Get("free"), ',');
  json hints = args.Has("hints") ? ReadJsonFile(args.Get("hints"), "--hints") : json::object();
  if (args.Has("hint")) AddHints(args.Get("hint"), &hints);
  json params = {{"board", BoardParams(args)}, {"options", options}};
  if (!hints.empty()) params["hints"] = hints;
  const bool mirror = args.Has("rim-radius-mm") || args.Has("rim-height-mm");
  if (args.Has("svp") || mirror || args.Has("svp-image")) {
    json svp = json::object();
    if (mirror) {
      OMNIRIG_CHECK(args.Has("rim-radius-mm") && args.Has("rim-height-mm"),
                    "--rim-radius-mm and --rim-height-mm go together");
      svp["mirror"] = {{"rim_radius_mm", args.GetDouble("rim-radius-mm")},
                       {"rim_height_mm", args.GetDouble("rim-height-mm")}};
    }
    if (args.Has("svp-image")) svp["image"] = args.Get("svp-image");
    params["svp"] = svp;
  }
  return params;
}

void Export(const CameraModel& camera, const ArgParser& args) {
  std::vector<std::string> warnings;
  if (args.Has("export-opencv")) {
    WriteFile(args.Get("export-opencv"), ToOpenCvOmnidir(camera, &warnings));
    for (const auto& w : warnings) std::cerr << "export-opencv: WARNING: " << w << "\n";
  }
  if (args.Has("export-kalibr")) {
    WriteFile(args.Get("export-kalibr"), ToKalibrOmniRadtan(camera, &warnings));
    for (const auto& w : warnings) std::cerr << "export-kalibr: WARNING: " << w << "\n";
  }
}

void PrintSummary(const CalibrationReport& report) {
  std::cerr << std::fixed << std::setprecision(4);
  for (const auto& image : report.images) {
    std::cerr << "  " << image.name << ": "
              << (image.used ? "RMS " + std::to_string(image.rms_px) + " px"
                             : "not used (" + image.reason + ")")
              << "\n";
  }
  std::cerr << "views used: " << report.num_views_used << " of " << report.images.size() << "\nRMS "
            << report.rms_px << " px; Euclidean corner error mean " << report.mean_px << " +- "
            << report.std_px << " px (std); RMS incl. rejected corners " << report.rms_all_px
            << " px\n";
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    std::cerr << "  " << std::setw(8) << UnifiedIntrinsics::kNames[i] << " = "
              << std::setprecision(6) << report.camera.intrinsics.params[i] << " +- "
              << report.intrinsics_std[i] << "\n";
  }
  std::cerr << report.solver.brief << "\n";
  if (report.svp) {
    const SvpCheckReport& svp = *report.svp;
    std::cerr << "SVP check on " << report.svp_image << ": ";
    if (!svp.found_circle_px) {
      std::cerr << "rim not found (" << svp.reason << ")\n";
    } else {
      const Eigen::Vector3d& c = *svp.found_circle_px;
      std::cerr << "rim at (" << c.x() << ", " << c.y() << ") radius " << c.z() << " px, centre "
                << svp.principal_point_offset_px << " px from the principal point";
      if (svp.predicted_circle_px) {
        std::cerr << "; against the prediction: centre " << svp.centre_offset_px << " px, radius "
                  << svp.radius_offset_px << " px";
      }
      std::cerr << "\n";
    }
  }
}

}  // namespace

int RunCalibrate(const Args& argv) {
  ArgParser args("calibrate",
                 "Calibrate a catadioptric camera (Mei's unified model) from board images.");
  AddBoardOptions({"8", "6", "40", "0", "0"}, &args);
  args.AddOption("o", "calib.json", "output JSON file");
  args.AddOption("export-opencv", "", "also write an OpenCV omnidir FileStorage YAML file");
  args.AddOption("export-kalibr", "", "also write a Kalibr omni-radtan camchain YAML file");
  args.AddOption("fix", "",
                 "comma-separated parameters to fix (xi,gamma_u,..,k5,skew,tangential,"
                 "principal_point,gamma); skew and k5 are fixed by default");
  args.AddOption("free", "", "comma-separated parameters to free (e.g. skew,k5)");
  args.AddOption("hint", "",
                 "outer corners: 'IMAGE:u,v,u,v,u,v,u,v;...' (ids 0, cols-1, last, "
                 "first of last row)");
  args.AddOption("hints", "", "JSON file {\"IMAGE\": [[u,v] x4]}");
  args.AddOption("overlays", "",
                 "write overlay_<image>.png files (and svp_overlay.png) into this directory");
  args.AddOption("threads", "2", "solver threads");
  args.AddFlag("svp",
               "single-viewpoint check: find the mirror rim and report it against the "
               "principal point (and the prediction, with the rim's dimensions)");
  args.AddOption("rim-radius-mm", "", "SVP check: mirror rim radius (mm); implies --svp");
  args.AddOption("rim-height-mm", "",
                 "SVP check: rim height above the mirror's focus (mm); implies --svp");
  args.AddOption("svp-image", "", "SVP check: image to check (default: the first used image)");
  args.SetPositional("IMAGES...", "board images (paths)");
  if (!args.Parse(argv)) return args.exit_code();
  OMNIRIG_CHECK(!args.positional().empty(), "no images given (see --help)");
  api::CalibrationRequest request = api::CalibrationRequestFromJson(ParamsFromArgs(args));
  request.options.calibrate.num_threads = args.GetInt("threads");
  const CalibrationReport report =
      CalibrateImages("", args.positional(), request.board, request.options, args.Get("overlays"),
                      ProgressSink{PrintProgress, nullptr});
  PrintSummary(report);
  WriteFile(args.Get("o"), api::CalibrationReportToJson(report).dump(2) + "\n");
  Export(report.camera, args);
  std::cerr << "wrote " << args.Get("o") << "\n";
  return 0;
}

}  // namespace omnirig::cli
