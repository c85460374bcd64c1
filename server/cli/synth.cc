// `omnirig synth`: renders one of the synthetic presets with its ground truth into a folder.
//
//   omnirig synth --preset mono-calib|stereo-board|stereo-sequence|stereo-loop --out DIR
//       [--width 1024 --height 768 --views 20 --frames 40 --scene room|street --noise 0
//        --blur 0 --vignetting 0 --seed 0 --supersampling 4 --threads 0 --grayscale
//        --video mp4|avi|mkv [--stacked] ...]
//       stereo-loop: [--loop-length 100 --laps 2 --frames (10 per metre) --same-lighting
//                     --motion-blur 0 --motion-blur-samples 5]

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <string>

#include "api/synth_json.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"
#include "engine/util/timer.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"

namespace omnirig::cli {
namespace {

void DeclareOptions(ArgParser* parser) {
  parser->AddOption("preset", "",
                    "what to render: mono-calib (one camera, board views), stereo-board (a "
                    "vertical stereo rig, board views seen by both cameras), stereo-sequence "
                    "(the rig moving through a textured scene) or stereo-loop (the rig driving "
                    "laps around a city block: closed loops with revisits)");
  parser->AddOption("out", "", "output folder (created): PNG images and ground_truth.json");
  parser->AddOption("width", "1024", "image width in pixels");
  parser->AddOption("height", "768", "image height in pixels");
  parser->AddOption("views", "20", "board views (mono-calib) or board pairs (stereo-board)");
  parser->AddOption("frames", "40",
                    "frames of stereo-sequence; of stereo-loop, 10 per metre of all laps unless "
                    "given");
  parser->AddOption("scene", "room", "stereo-sequence scene: room or street");
  parser->AddOption("path-length", "6", "stereo-sequence path length in metres");
  parser->AddOption("frame-interval", "0.1", "stereo-sequence seconds between frames");
  parser->AddOption("loop-length", "100", "stereo-loop: length of one lap in metres (40 .. 400)");
  parser->AddOption("laps", "2", "stereo-loop: laps driven around the block");
  parser->AddFlag("same-lighting",
                  "stereo-loop: every lap under the same light (by default each lap has its own "
                  "gain, tint and sun)");
  parser->AddOption("motion-blur", "0",
                    "stereo-sequence and stereo-loop: exposure in seconds over which the rig's "
                    "motion blurs each image (0: none)");
  parser->AddOption("motion-blur-samples", "5",
                    "poses averaged per image with --motion-blur (each costs one render)");
  parser->AddOption("baseline", "0.1",
                    "stereo rigs: distance in metres of cam1 along cam0's +z axis (vertical rig)");
  parser->AddOption("board-cols", "8", "board inner corners along its width");
  parser->AddOption("board-rows", "6", "board inner corners along its height");
  parser->AddOption("square-size", "0.04", "board square size in metres");
  parser->AddOption("board-margin", "0.03", "white margin around the squares in metres");
  parser->AddOption("min-distance", "0.35", "nearest board distance in metres");
  parser->AddOption("max-distance", "1.2", "farthest board distance in metres");
  parser->AddOption("max-tilt", "50", "largest board tilt against the line of sight, degrees");
  parser->AddFlag("plain-background", "board presets: no textured room behind the board");
  parser->AddOption("noise", "0", "Gaussian image noise, standard deviation in grey levels");
  parser->AddOption("blur", "0", "Gaussian blur (optics), sigma in pixels");
  parser->AddOption("vignetting", "0", "brightness loss at the mirror rim, fraction in [0, 1]");
  parser->AddOption("supersampling", "4", "s: s x s samples per pixel (boards are exact anyway)");
  parser->AddFlag("grayscale", "write 8-bit grey images instead of BGR colour");
  parser->AddOption("video", "",
                    "stereo-sequence: write videos instead of PNG folders: mp4 (mp4v), avi (MJPG) "
                    "or mkv (FFV1, lossless) as DIR/cam0.EXT and DIR/cam1.EXT");
  parser->AddFlag("stacked", "with --video: one DIR/stacked.EXT, cam0 on top of cam1");
  parser->AddOption("seed", "0", "seed of poses, textures and noise: same seed, same output");
  parser->AddOption("threads", "0", "render threads, 0 = all cores");
}

synth::RenderOptions RenderOptionsFromArgs(const ArgParser& args) {
  synth::RenderOptions render;
  render.supersampling = args.GetInt("supersampling");
  render.noise_sigma = args.GetDouble("noise");
  render.blur_sigma_px = args.GetDouble("blur");
  render.vignetting = args.GetDouble("vignetting");
  render.num_threads = args.GetInt("threads");
  render.grayscale = args.Has("grayscale");
  return render;
}

synth::CheckerboardSpec BoardFromArgs(const ArgParser& args) {
  synth::CheckerboardSpec board;
  board.cols = args.GetInt("board-cols");
  board.rows = args.GetInt("board-rows");
  board.square_size_m = args.GetDouble("square-size");
  board.margin_m = args.GetDouble("board-margin");
  return board;
}

synth::BoardPoseOptions PosesFromArgs(const ArgParser& args) {
  synth::BoardPoseOptions poses;
  poses.min_distance_m = args.GetDouble("min-distance");
  poses.max_distance_m = args.GetDouble("max-distance");
  poses.max_tilt_deg = args.GetDouble("max-tilt");
  return poses;
}

Rigid3d Cam0FromCam1FromArgs(const ArgParser& args) {
  Rigid3d cam0_from_cam1 = synth::DefaultCam0FromCam1();
  cam0_from_cam1.translation = Eigen::Vector3d(0.0, 0.0, args.GetDouble("baseline"));
  return cam0_from_cam1;
}

uint64_t SeedFromArgs(const ArgParser& args) {
  const std::string text = args.Get("seed");
  try {
    size_t used = 0;
    const unsigned long long seed = std::stoull(text, &used);
    if (used == text.size() && text.find('-') == std::string::npos) return seed;
  } catch (const std::exception&) {
  }
  throw InvalidArgument("--seed expects a non-negative integer, got '" + text + "'");
}

// What stereo-sequence and stereo-loop share.
synth::StereoSequenceOptions SequenceOptionsFromArgs(const ArgParser& args, uint64_t seed) {
  synth::StereoSequenceOptions options;
  options.frame_interval_s = args.GetDouble("frame-interval");
  options.motion_blur_exposure_s = args.GetDouble("motion-blur");
  options.motion_blur_samples = args.GetInt("motion-blur-samples");
  options.width = args.GetInt("width");
  options.height = args.GetInt("height");
  options.cam0_from_cam1 = Cam0FromCam1FromArgs(args);
  options.render = RenderOptionsFromArgs(args);
  options.seed = seed;
  return options;
}

// Progress on stderr: rewritten in place (\r) on a terminal; one plain line per step when
// stderr is a file or a pipe, so that a log reads line by line.
ProgressSink PrintingProgress(bool terminal) {
  ProgressSink progress;
  progress.report = [terminal](double fraction, const std::string&, const std::string& message) {
    std::cerr << (terminal ? "\r" : "") << "rendered " << message << " ("
              << static_cast<int>(100 * fraction + 0.5) << "%)" << (terminal ? "" : "\n")
              << std::flush;
  };
  return progress;
}

// What mono-calib and stereo-board share: image size, board, its poses, background, rendering.
template <typename Options>
Options BoardViewOptionsFromArgs(const ArgParser& args, uint64_t seed) {
  Options options;
  options.width = args.GetInt("width");
  options.height = args.GetInt("height");
  options.board = BoardFromArgs(args);
  options.poses = PosesFromArgs(args);
  options.textured_background = !args.Has("plain-background");
  options.render = RenderOptionsFromArgs(args);
  options.seed = seed;
  return options;
}

void MonoCalibPreset(const ArgParser& args, uint64_t seed, const ProgressSink& progress,
                     const std::string& out) {
  auto options = BoardViewOptionsFromArgs<synth::MonoCalibrationOptions>(args, seed);
  options.num_views = args.GetInt("views");
  api::WriteMonoCalibrationSet(synth::MakeMonoCalibrationSet(options, progress), out);
}

void StereoBoardPreset(const ArgParser& args, uint64_t seed, const ProgressSink& progress,
                       const std::string& out) {
  auto options = BoardViewOptionsFromArgs<synth::StereoBoardOptions>(args, seed);
  options.num_pairs = args.GetInt("views");
  options.cam0_from_cam1 = Cam0FromCam1FromArgs(args);
  api::WriteStereoBoardSet(synth::MakeStereoBoardSet(options, progress), out);
}

void StereoSequencePreset(const ArgParser& args, uint64_t seed, const ProgressSink& progress,
                          const std::string& out) {
  const std::string scene = args.Get("scene");
  OMNIRIG_CHECK(scene == "room" || scene == "street",
                "--scene must be room or street, got '" << scene << "'");
  synth::StereoSequenceOptions options = SequenceOptionsFromArgs(args, seed);
  options.environment = scene == "room" ? synth::StereoSequenceOptions::Environment::kRoom
                                        : synth::StereoSequenceOptions::Environment::kStreet;
  options.num_frames = args.GetInt("frames");
  options.path_length_m = args.GetDouble("path-length");
  const std::string video = args.Get("video");
  if (!video.empty() && video != "mp4" && video != "avi" && video != "mkv") {
    throw InvalidArgument("--video must be mp4, avi or mkv, got '" + video + "'");
  }
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options, progress);
  if (video.empty()) {
    api::WriteStereoSequence(sequence, scene, out);
  } else {
    api::WriteStereoSequenceVideos(sequence, scene, out, video, args.Has("stacked"));
  }
}

void StereoLoopPreset(const ArgParser& args, uint64_t seed, const ProgressSink& progress,
                      const std::string& out) {
  synth::StereoSequenceOptions options = SequenceOptionsFromArgs(args, seed);
  options.environment = synth::StereoSequenceOptions::Environment::kCityBlock;
  options.path_length_m = args.GetDouble("loop-length");
  options.num_laps = args.GetInt("laps");
  OMNIRIG_CHECK(options.path_length_m >= 40.0 && options.path_length_m <= 400.0,
                "--loop-length must be in [40, 400] metres, got " << options.path_length_m);
  OMNIRIG_CHECK(options.num_laps >= 1 && options.num_laps <= 100,
                "--laps must be in [1, 100], got " << options.num_laps);
  options.num_frames =
      args.Has("frames")
          ? args.GetInt("frames")
          : static_cast<int>(std::lround(10.0 * options.num_laps * options.path_length_m));
  options.lighting_change = !args.Has("same-lighting");
  // Frame by frame: 2,000 full-size pairs do not fit in memory.
  for (const char* camera : {"cam0", "cam1"}) {
    std::filesystem::create_directories(std::filesystem::path(out) / camera);
  }
  const synth::StereoSequence sequence = synth::RenderStereoSequence(
      options,
      [&out](int, const std::string& name, const cv::Mat& cam0_image, const cv::Mat& cam1_image) {
        api::WriteStereoFrame(name, cam0_image, cam1_image, out);
      },
      progress);
  api::WriteStereoSequenceGroundTruth(sequence, "city-block", out);
}

void RunPreset(const ArgParser& args, const std::string& preset, const std::string& out,
               bool terminal) {
  using Preset = void (*)(const ArgParser&, uint64_t, const ProgressSink&, const std::string&);
  const std::map<std::string, Preset> kPresets = {{"mono-calib", MonoCalibPreset},
                                                  {"stereo-board", StereoBoardPreset},
                                                  {"stereo-sequence", StereoSequencePreset},
                                                  {"stereo-loop", StereoLoopPreset}};
  const auto found = kPresets.find(preset);
  if (found == kPresets.end()) {
    throw InvalidArgument(
        "--preset must be mono-calib, stereo-board, stereo-sequence or stereo-loop, got '" +
        preset + "'");
  }
  found->second(args, SeedFromArgs(args), PrintingProgress(terminal), out);
}

}  // namespace

int RunSynth(const Args& arguments) {
  ArgParser args("synth",
                 "Renders synthetic omnidirectional (catadioptric) images through Mei's unified "
                 "model, with ground truth: intrinsics, every pose, board corners and their exact "
                 "pixel projections, the scene's primitives (DIR/ground_truth.json), and for "
                 "sequences DIR/trajectory.tum. Mono images are DIR/NAME.png; stereo images are "
                 "DIR/cam0/NAME.png and DIR/cam1/NAME.png, pairs matched by NAME; with --video, "
                 "DIR/cam0.EXT and DIR/cam1.EXT (or DIR/stacked.EXT).");
  DeclareOptions(&args);
  if (!args.Parse(arguments)) return args.exit_code();
  const std::string preset = args.Get("preset"), out = args.Get("out");
  if (preset.empty() || out.empty()) {
    std::cerr << "omnirig synth: --preset and --out are required (see --help)\n";
    return 2;
  }
  OMNIRIG_CHECK(args.positional().empty(),
                "unexpected argument '" << args.positional().front() << "'");
  // Fail on an unwritable folder before rendering, not after.
  std::error_code error;
  std::filesystem::create_directories(out, error);
  OMNIRIG_CHECK(!error && std::filesystem::is_directory(out),
                "cannot create the output folder '" << out << "'");
  const Timer timer;
  const bool terminal = isatty(STDERR_FILENO) != 0;
  RunPreset(args, preset, out, terminal);
  std::cerr << (terminal ? "\n" : "") << "wrote " << preset << " to " << out << " in "
            << timer.ElapsedSeconds() << " s\n";
  return 0;
}

}  // namespace omnirig::cli
