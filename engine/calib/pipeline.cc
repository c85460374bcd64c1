#include "engine/calib/pipeline.h"

#include <algorithm>
#include <map>
#include <optional>
#include <sstream>
#include <utility>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/frame_selection.h"
#include "engine/features/image.h"
#include "engine/util/option_check.h"
#include "engine/util/parallel.h"
#include "engine/util/progress_range.h"
#include "engine/util/timer.h"

namespace omnirig {
namespace {

cv::Point2d ToCv(const Eigen::Vector2d& p) { return cv::Point2d(p.x(), p.y()); }

// Reads one image; an empty Mat (with `reason` set) when it is missing, unreadable or truncated.
cv::Mat ReadImage(const ImageReader& read, const std::string& name, std::string* reason,
                  int imread_flags = cv::IMREAD_COLOR) {
  cv::Mat image;
  try {
    image = read(name, imread_flags);
  } catch (const cv::Exception&) {
    image = cv::Mat();
  }
  if (image.empty()) *reason = "cannot read the image (missing, unreadable or truncated file)";
  return image;
}

// The first readable image fixes the size; views of another size become unused with the reason
// (their detections, made in parallel before the size was known, are dropped).
void CheckImageSizes(const std::vector<cv::Size>& sizes, std::vector<CalibrationView>* views,
                     int* width, int* height) {
  for (size_t i = 0; i < sizes.size(); ++i) {
    if (sizes[i].empty()) continue;
    if (*width == 0) {
      *width = sizes[i].width;
      *height = sizes[i].height;
    } else if (sizes[i].width != *width || sizes[i].height != *height) {
      std::ostringstream os;
      os << "image size " << sizes[i].width << "x" << sizes[i].height
         << " differs from the first image's " << *width << "x" << *height;
      (*views)[i].detection = BoardDetection();
      (*views)[i].detection.reason = os.str();
    }
  }
}

// Reads each image and detects the board in it, on options.calibrate.num_threads threads
// (images are independent; each worker holds one image at a time). The results are in input
// order whatever the scheduling.
std::vector<CalibrationView> DetectAll(const ImageReader& read,
                                       const std::vector<std::string>& names,
                                       const BoardSpec& board,
                                       const ImageCalibrationOptions& options,
                                       const DetectOptions& detect_options, int* width,
                                       int* height, const ProgressSink& progress) {
  std::vector<CalibrationView> views(names.size());
  std::vector<cv::Size> sizes(names.size());
  auto detect_one = [&](int i, const ProgressSink& cancellation) {
    cancellation.ThrowIfCancelled();
    views[i].name = names[i];
    const cv::Mat image = ReadImage(read, names[i], &views[i].detection.reason);
    if (image.empty()) return;
    sizes[i] = image.size();
    DetectOptions detect = detect_options;
    const auto hint = options.hints.find(names[i]);
    if (hint != options.hints.end()) detect.outer_corners_hint_px = hint->second;
    views[i].detection = DetectBoard(image, board, detect);
  };
  size_t done = 0;
  RunTasks(static_cast<int>(names.size()), options.calibrate.num_threads, progress, detect_one,
           [&](int i) {
             ++done;
             progress.Report(0.5 * done / names.size(), "detect",
                             names[i] + (views[i].detection.found
                                             ? ": found"
                                             : ": " + views[i].detection.reason));
           });
  progress.ThrowIfCancelled();
  CheckImageSizes(sizes, &views, width, height);
  return views;
}

// When no view shows the board at the given size: the first board size near it (one more of
// both, cols and rows swapped, one more or one less of either) that an image shows, searched on up to three
// readable images with the cheap detector attempts only. Returns the message for the user.
std::string DescribeBoardSizeMismatch(const ImageReader& read,
                                      const std::vector<CalibrationView>& views,
                                      const BoardSpec& board) {
  // Largest first: a smaller size is found inside a larger board, not the other way round.
  std::vector<std::pair<int, int>> sizes = {{board.cols + 1, board.rows + 1},
                                            {board.rows, board.cols},
                                            {board.cols + 1, board.rows},
                                            {board.cols, board.rows + 1},
                                            {board.cols - 1, board.rows},
                                            {board.cols, board.rows - 1},
                                            {board.cols - 1, board.rows - 1}};
  DetectOptions quick;
  quick.try_enhanced = false;
  quick.refine_subpixel = false;
  int tried = 0;
  for (const CalibrationView& view : views) {
    if (tried >= 3) break;
    std::string unused;
    const cv::Mat image = ReadImage(read, view.name, &unused);
    if (image.empty()) continue;
    ++tried;
    for (const auto& [cols, rows] : sizes) {
      if (cols < 2 || rows < 2 || (cols == board.cols && rows == board.rows)) continue;
      BoardSpec other = board;
      other.cols = cols;
      other.rows = rows;
      if (!DetectBoard(image, other, quick).found) continue;
      std::ostringstream os;
      os << "the board size looks wrong: no image shows " << board.cols << "x" << board.rows
         << " inner corners, but " << view.name << " shows a board of " << cols << "x" << rows
         << " inner corners (cols and rows count the inner corners, one less than the squares)";
      return os.str();
    }
  }
  std::ostringstream os;
  os << "no image shows a checkerboard of " << board.cols << "x" << board.rows
     << " inner corners (nor a size near it); check the board's cols and rows (inner corners, "
        "one less than the squares) and that the board is in view";
  return os.str();
}

// The second pass over the views the first one missed (no hint, readable, of the calibration's
// size), in parallel: with the model of a first calibration, a partial grid grown to the whole
// board (RedetectWithModel); then, with `detect`, the detector with every variant. Returns true
// when it found any.
bool DetectMissed(const ImageReader& read, const BoardSpec& board,
                  const ImageCalibrationOptions& options, const CameraModel* model, bool detect,
                  int width, int height, const ProgressSink& progress,
                  std::vector<CalibrationView>* views) {
  std::vector<int> missed;
  for (size_t i = 0; i < views->size(); ++i) {
    const CalibrationView& view = (*views)[i];
    if (!view.detection.found && !options.hints.count(view.name)) missed.push_back(i);
  }
  std::vector<std::optional<BoardDetection>> found(missed.size());
  auto detect_one = [&](int k, const ProgressSink& cancellation) {
    cancellation.ThrowIfCancelled();
    const cv::Mat image = read((*views)[missed[k]].name, cv::IMREAD_COLOR);
    if (image.empty() || image.cols != width || image.rows != height) return;
    BoardDetection detection;
    // Growing a partial grid of X-corners with the model finds checkerboards (a ChArUco board
    // is one); an AprilGrid's detector already takes partial views.
    if (model && board.type != BoardSpec::Type::kAprilgrid) {
      detection = RedetectWithModel(image, board, *model, options.detect);
    }
    if (!detection.found && detect) detection = DetectBoard(image, board, options.detect);
    if (model || detect) found[k] = std::move(detection);
  };
  RunTasks(static_cast<int>(missed.size()), options.calibrate.num_threads, progress, detect_one,
           [&](int k) {
             if (!found[k]) return;
             progress.Report(0.8, "redetect",
                             (*views)[missed[k]].name +
                                 (found[k]->found ? ": found (" + found[k]->method + ")"
                                                  : ": " + found[k]->reason));
           });
  bool any = false;
  for (size_t k = 0; k < missed.size(); ++k) {
    if (!found[k]) continue;
    BoardDetection& view_detection = (*views)[missed[k]].detection;
    if (found[k]->found) {
      view_detection = std::move(*found[k]);
      any = true;
    } else if (detect) {
      // Without a new detector run the first pass's reason stays: it says more to a user than
      // the model-based search's.
      view_detection.reason = found[k]->reason;
    }
  }
  return any;
}

// The first pass: every image read and searched, leaving out the detector's costly variants when
// a second pass with a model follows (growing a view's partial grid with the model of the other
// views takes a tenth of their time, bench_calib profile); with too few views for a first model,
// the costly variants then run on every view missed. Returns whether every variant has run.
bool DetectFirstPass(const ImageReader& read, const std::vector<std::string>& names,
                     const BoardSpec& board, const ImageCalibrationOptions& options, int* width,
                     int* height, const ProgressSink& progress,
                     std::vector<CalibrationView>* views) {
  DetectOptions first_pass = options.detect;
  first_pass.try_costly_variants =
      options.detect.try_costly_variants && !options.redetect_with_model;
  *views = DetectAll(read, names, board, options, first_pass, width, height, progress);
  OMNIRIG_CHECK(*width > 0,
                "calibration: none of the " << names.size() << " images could be read");
  if (first_pass.try_costly_variants == options.detect.try_costly_variants) return true;
  const int num_found = static_cast<int>(
      std::count_if(views->begin(), views->end(),
                    [](const CalibrationView& view) { return view.detection.found; }));
  if (num_found >= options.calibrate.min_views) return false;
  DetectMissed(read, board, options, nullptr, true, *width, *height, progress, views);
  return true;
}

// The first readable frame fixes the size; a frame of another size is unreadable with the reason.
bool CheckFrameSize(const cv::Size& size, int* width, int* height, std::string* detail) {
  if (*width == 0) {
    *width = size.width;
    *height = size.height;
    return true;
  }
  if (size.width == *width && size.height == *height) return true;
  std::ostringstream os;
  os << "image size " << size.width << "x" << size.height << " differs from the first image's "
     << *width << "x" << *height;
  *detail = os.str();
  return false;
}

// Step 1 of a long input (frame_selection.h): the cheap test on every frame, in parallel. Fills
// the frames' sizes (empty when unreadable) and the whole boards' screened corners.
void ScreenFrames(const ImageReader& read, const std::vector<std::string>& names,
                  const BoardSpec& board, const ImageCalibrationOptions& options,
                  const ProgressSink& progress, std::vector<FrameReport>* frames,
                  std::vector<cv::Size>* sizes,
                  std::vector<std::vector<Eigen::Vector2d>>* screened) {
  const bool cheap_test = board.type == BoardSpec::Type::kCheckerboard;
  auto screen_one = [&](int i, const ProgressSink& cancellation) {
    cancellation.ThrowIfCancelled();
    cv::Mat grey = ReadImage(read, names[i], &(*frames)[i].detail,
                             cheap_test ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
    if (grey.empty()) return;
    (*sizes)[i] = grey.size();
    if (!cheap_test) return;
    if (grey.channels() == 3) cv::cvtColor(grey, grey, cv::COLOR_BGR2GRAY);
    (*screened)[i] = ScreenFrame(grey, board);
  };
  size_t done = 0;
  RunTasks(static_cast<int>(names.size()), options.calibrate.num_threads, progress, screen_one,
           [&](int i) {
             ++done;
             if (done % 20 != 0 && done != names.size()) return;
             progress.Report(0.25 * done / names.size(), "screen",
                             names[i] + ((*screened)[i].empty() ? ": no whole board" : ": board"));
           });
  progress.ThrowIfCancelled();
}

// Steps 1-4 of a long input (frame_selection.h): returns the chosen views, fully detected, and
// fills every frame's report (the used ones and the outliers are set after the calibration).
std::vector<CalibrationView> DetectLongInput(const ImageReader& read,
                                             const std::vector<std::string>& names,
                                             const BoardSpec& board,
                                             const ImageCalibrationOptions& options, int* width,
                                             int* height, const ProgressSink& progress,
                                             std::vector<FrameReport>* frames) {
  const size_t n = names.size();
  frames->assign(n, FrameReport());
  std::vector<cv::Size> sizes(n);
  std::vector<std::vector<Eigen::Vector2d>> screened(n);
  ScreenFrames(read, names, board, options, progress, frames, &sizes, &screened);
  const bool cheap_test = board.type == BoardSpec::Type::kCheckerboard;
  for (size_t i = 0; i < n; ++i) {
    FrameReport& frame = (*frames)[i];
    frame.name = names[i];
    if (sizes[i].empty() || !CheckFrameSize(sizes[i], width, height, &frame.detail)) {
      frame.reason = "unreadable";
      screened[i].clear();
    } else if (cheap_test && screened[i].empty()) {
      frame.reason = "no_board";
    }
  }
  OMNIRIG_CHECK(*width > 0, "calibration: none of the " << n << " images could be read");
  const std::vector<int> duplicate_of = MarkNearDuplicates(
      screened, options.selection.near_duplicate_fraction * std::min(*width, *height));
  std::vector<std::string> candidates;
  std::vector<size_t> frame_of;
  for (size_t i = 0; i < n; ++i) {
    FrameReport& frame = (*frames)[i];
    if (duplicate_of[i] >= 0) {
      frame.reason = "near_duplicate_of";
      frame.duplicate_of = names[duplicate_of[i]];
    } else if (frame.reason.empty()) {
      candidates.push_back(names[i]);
      frame_of.push_back(i);
    }
  }
  if (candidates.empty()) return {};
  DetectOptions detect = options.detect;
  detect.try_costly_variants = false;  // plenty of frames: the cheap variants suffice
  int detect_width = 0, detect_height = 0;
  std::vector<CalibrationView> views = DetectAll(read, candidates, board, options, detect,
                                                 &detect_width, &detect_height,
                                                 SubRange(progress, 0.25, 0.75));
  const std::vector<int> chosen =
      SelectViews(views, *width, *height, board, options.selection.max_views, options.calibrate);
  for (size_t k = 0; k < views.size(); ++k) {
    FrameReport& frame = (*frames)[frame_of[k]];
    if (!views[k].detection.found) {
      frame.reason = "detection_failed";
      frame.detail = views[k].detection.reason;
    } else {
      frame.reason = "not_selected";
    }
  }
  std::vector<CalibrationView> selected;
  for (int k : chosen) {
    (*frames)[frame_of[k]].reason.clear();  // used or outlier, after the calibration
    selected.push_back(std::move(views[k]));
  }
  return selected;
}

// The frames of a short input from its views and calibration (every view detected and offered).
std::vector<FrameReport> FramesOfViews(const std::vector<CalibrationView>& views) {
  std::vector<FrameReport> frames;
  for (const CalibrationView& view : views) {
    FrameReport frame;
    frame.name = view.name;
    const std::string& reason = view.detection.reason;
    if (!view.detection.found) {
      const bool unreadable =
          reason.rfind("cannot read the image", 0) == 0 || reason.rfind("image size ", 0) == 0;
      frame.reason = unreadable ? "unreadable" : "detection_failed";
      frame.detail = reason;
    }
    frames.push_back(std::move(frame));
  }
  return frames;
}

// Marks the calibrated views of `frames` used, or outliers with the calibration's reason.
void MarkCalibratedFrames(const CalibrationReport& report, std::vector<FrameReport>* frames) {
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < frames->size(); ++i) index.emplace((*frames)[i].name, i);
  for (const CalibrationImageReport& image : report.images) {
    const auto it = index.find(image.name);
    if (it == index.end() || !(*frames)[it->second].reason.empty()) continue;
    FrameReport& frame = (*frames)[it->second];
    frame.used = image.used;
    frame.reason = image.used ? "used" : "outlier";
    frame.detail = image.used ? "" : image.reason;
  }
}

// The SVP check on the requested image (or the first used one) with the calibrated model.
void RunSvpCheck(const ImageReader& read, const SvpOptions& svp,
                 const std::filesystem::path& overlay_dir, CalibrationReport* report) {
  std::string name = svp.image;
  for (const CalibrationImageReport& image : report->images) {
    if (name.empty() && image.used) name = image.name;
  }
  report->svp_image = name;
  report->svp.emplace();
  report->svp->principal_point_px =
      Eigen::Vector2d(report->camera.intrinsics.u0(), report->camera.intrinsics.v0());
  std::string reason;
  const cv::Mat image = ReadImage(read, name, &reason);
  if (image.empty()) {
    report->svp->reason = name + ": " + reason;
    return;
  }
  try {
    *report->svp = svp.mirror ? CheckSingleViewpoint(image, report->camera, *svp.mirror, svp.check)
                              : DetectRim(image, report->camera, svp.check);
  } catch (const InvalidArgument& e) {
    report->svp->reason = e.what();  // e.g. the rim does not project with this model
  }
  if (!overlay_dir.empty()) {
    std::filesystem::create_directories(overlay_dir);
    cv::imwrite((overlay_dir / kSvpOverlayFileName).string(), DrawSvpOverlay(image, *report->svp));
  }
}

}  // namespace

void SvpOptions::Check() const {
  if (mirror) mirror->Check();
  check.Check();
}

void ImageCalibrationOptions::Check() const {
  detect.Check();
  calibrate.Check();
  OMNIRIG_CHECK_POSITIVE(overlay_error_scale);
  selection.Check();
  if (svp) svp->Check();
  for (const auto& [name, hint] : hints) {
    for (const auto& corner : hint) {
      OMNIRIG_CHECK(corner.allFinite(), "hint for '" << name << "' is not finite");
    }
  }
}

std::string OverlayFileName(const std::string& image_name) {
  std::string name = image_name;
  for (char& c : name) {
    if (c == '/' || c == '\\') c = '_';
  }
  // The overlay is a PNG whatever the image was: its extension is replaced, not doubled.
  const size_t dot = name.rfind('.');
  if (dot != std::string::npos && dot > 0) name.resize(dot);
  return "overlay_" + name + ".png";
}

cv::Mat DrawCalibrationOverlay(const cv::Mat& image, const CalibrationImageReport& report,
                               double error_scale) {
  cv::Mat overlay;
  if (image.channels() == 1) {
    cv::cvtColor(image, overlay, cv::COLOR_GRAY2BGR);
  } else {
    overlay = image.clone();
  }
  const cv::Scalar green(0, 255, 0), red(0, 0, 255), yellow(0, 255, 255), magenta(255, 0, 255);
  for (size_t i = 0; i < report.corners_px.size(); ++i) {
    const bool inlier = i >= report.inlier.size() || report.inlier[i];
    cv::circle(overlay, ToCv(report.corners_px[i]), 3, inlier ? green : magenta, 1, cv::LINE_AA);
    if (i >= report.reprojected_px.size()) continue;
    const Eigen::Vector2d error = report.reprojected_px[i] - report.corners_px[i];
    cv::drawMarker(overlay, ToCv(report.reprojected_px[i]), red, cv::MARKER_CROSS, 5, 1);
    cv::line(overlay, ToCv(report.corners_px[i]), ToCv(report.corners_px[i] + error_scale * error),
             yellow, 1, cv::LINE_AA);
  }
  std::ostringstream caption;
  caption.precision(3);
  if (report.used) {
    caption << report.name << ": RMS " << report.rms_px << " px, errors x" << error_scale;
  } else {
    caption << report.name << ": not used (" << report.reason << ")";
  }
  cv::putText(overlay, caption.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(overlay, caption.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return overlay;
}

namespace {

void CheckArguments(const std::vector<std::string>& names, const BoardSpec& board,
                    const ImageCalibrationOptions& options) {
  board.Check();
  options.Check();
  OMNIRIG_CHECK(!names.empty(), "calibration: no images");
  for (const auto& [name, hint] : options.hints) {
    OMNIRIG_CHECK(std::find(names.begin(), names.end(), name) != names.end(),
                  "hints: no image named '" << name << "'");
  }
  if (options.svp && !options.svp->image.empty()) {
    OMNIRIG_CHECK(std::find(names.begin(), names.end(), options.svp->image) != names.end(),
                  "svp: no image named '" << options.svp->image << "'");
  }
}

// One overlay per image of the report (OverlayFileName), in overlay_dir.
void WriteOverlays(const ImageReader& read, const CalibrationReport& report,
                   const ImageCalibrationOptions& options,
                   const std::filesystem::path& overlay_dir) {
  std::filesystem::create_directories(overlay_dir);
  for (const CalibrationImageReport& image_report : report.images) {
    const cv::Mat image = read(image_report.name, cv::IMREAD_COLOR);
    if (image.empty()) continue;
    cv::imwrite((overlay_dir / OverlayFileName(image_report.name)).string(),
                DrawCalibrationOverlay(image, image_report, options.overlay_error_scale));
  }
}

}  // namespace

CalibrationReport CalibrateImages(const ImageReader& read,
                                  const std::vector<std::string>& names, const BoardSpec& board,
                                  const ImageCalibrationOptions& options,
                                  const std::filesystem::path& overlay_dir,
                                  const ProgressSink& progress) {
  CheckArguments(names, board, options);
  int width = 0, height = 0;
  Timer timer;
  std::vector<CalibrationView> views;
  // A long input (a recording's frames): screened, near duplicates skipped, views chosen.
  const int max_views = options.selection.max_views;
  const int num_frames = static_cast<int>(names.size());
  const bool long_input = max_views > 0 && num_frames > max_views &&
                          num_frames > options.selection.long_input_frames;
  std::vector<FrameReport> frames;
  bool every_variant_tried = true;
  if (long_input) {
    views = DetectLongInput(read, names, board, options, &width, &height, progress, &frames);
  } else {
    every_variant_tried =
        DetectFirstPass(read, names, board, options, &width, &height, progress, &views);
  }
  const double detect_s = timer.ElapsedSeconds();
  if (board.type == BoardSpec::Type::kCheckerboard && options.hints.empty() &&
      std::none_of(views.begin(), views.end(),
                   [](const CalibrationView& view) { return view.detection.found; })) {
    if (long_input) {
      // The size check reads the first frames; the frames' own reasons follow.
      for (const std::string& name : names) views.push_back({name, BoardDetection()});
    }
    std::ostringstream os;
    os << DescribeBoardSizeMismatch(read, views, board) << ":";
    for (size_t i = 0; i < views.size() && i < 20; ++i) {
      os << "\n  " << views[i].name << ": "
         << (long_input ? frames[i].reason + (frames[i].detail.empty() ? "" : " (" + frames[i].detail + ")")
                        : views[i].detection.reason);
    }
    if (views.size() > 20) os << "\n  ... and " << views.size() - 20 << " more";
    throw InvalidArgument(os.str());
  }
  CalibrationReport report =
      Calibrate(views, width, height, board, options.calibrate, SubRange(progress, 0.5, 0.8));
  timer.Restart();
  // A long input offers more views than the cap: no second pass for the views missed.
  if (options.redetect_with_model && !long_input &&
      DetectMissed(read, board, options, &report.camera, !every_variant_tried, width, height,
                   progress, &views)) {
    const double redetect_s = timer.ElapsedSeconds();
    report =
        Calibrate(views, width, height, board, options.calibrate, SubRange(progress, 0.85, 0.95));
    report.timings.redetect_s = redetect_s;
  } else {
    report.timings.redetect_s = timer.ElapsedSeconds();
  }
  if (!long_input) frames = FramesOfViews(views);
  MarkCalibratedFrames(report, &frames);
  report.frames = std::move(frames);
  report.max_views = long_input ? max_views : 0;
  report.timings.detect_s = detect_s;
  if (!overlay_dir.empty()) WriteOverlays(read, report, options, overlay_dir);
  if (options.svp) {
    progress.Report(0.97, "svp", "single-viewpoint check");
    RunSvpCheck(read, *options.svp, overlay_dir, &report);
  }
  progress.Report(1.0, "done",
                  std::to_string(report.num_views_used) + " views, RMS " +
                      std::to_string(report.rms_px) + " px");
  return report;
}

CalibrationReport CalibrateImages(const std::filesystem::path& dir,
                                  const std::vector<std::string>& names, const BoardSpec& board,
                                  const ImageCalibrationOptions& options,
                                  const std::filesystem::path& overlay_dir,
                                  const ProgressSink& progress) {
  return CalibrateImages(FolderImageReader(dir), names, board, options, overlay_dir, progress);
}

}  // namespace omnirig
