#include "engine/dense/spherical_rectification.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <list>
#include <mutex>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig::dense {
namespace {

// Radius of the largest circle around the principal point inside the image (pixel centres
// from 0 to size - 1).
double InscribedRadius(const CameraModel& camera) {
  const double u0 = camera.intrinsics.u0(), v0 = camera.intrinsics.v0();
  return std::min({u0, camera.width - 1.0 - u0, v0, camera.height - 1.0 - v0});
}

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// A rotation whose third column is `pole` (unit), the first as close to cam0's x axis as the
// pole allows.
Eigen::Matrix3d FrameAroundPole(const Eigen::Vector3d& pole) {
  Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  if (std::abs(pole.dot(x)) > 0.9) x = Eigen::Vector3d::UnitY();
  x = (x - x.dot(pole) * pole).normalized();
  Eigen::Matrix3d frame;
  frame.col(0) = x;
  frame.col(1) = pole.cross(x);
  frame.col(2) = pole;
  return frame;
}

// The range of angles from the pole, in cam0's frame, of the bearings seen inside the inscribed
// circles of both images (a coarse sampling of the disks, widened by one sample's angle).
std::pair<double, double> ThetaRange(const StereoRig& rig, const Eigen::Vector3d& pole,
                                     double step_rad) {
  double lo = M_PI, hi = 0.0;
  const Eigen::Matrix3d cam0_from_cam1 = rig.cam0_from_cam1.rotation.toRotationMatrix();
  for (int camera = 0; camera < 2; ++camera) {
    const CameraModel& model = camera == 0 ? rig.cam0 : rig.cam1;
    const double radius = InscribedRadius(model);
    const double u0 = model.intrinsics.u0(), v0 = model.intrinsics.v0();
    constexpr double kSamplePx = 4.0;
    for (double dv = -radius; dv <= radius; dv += kSamplePx) {
      for (double du = -radius; du <= radius; du += kSamplePx) {
        if (du * du + dv * dv > radius * radius) continue;
        const std::optional<Eigen::Vector3d> bearing =
            Lift(model.intrinsics, Eigen::Vector2d(u0 + du, v0 + dv));
        if (!bearing) continue;
        const Eigen::Vector3d in_cam0 =
            camera == 0 ? *bearing : Eigen::Vector3d(cam0_from_cam1 * *bearing);
        const double theta = AngleBetween(pole, in_cam0);
        lo = std::min(lo, theta);
        hi = std::max(hi, theta);
      }
    }
  }
  OMNIRIG_CHECK(hi > lo, "no pixel of the images lifts to a bearing");
  return {std::max(0.0, lo - 4.0 * step_rad), std::min(M_PI, hi + 4.0 * step_rad)};
}

}  // namespace

void SphericalGridOptions::Check() const {
  OMNIRIG_CHECK(step_rad == 0.0 || (step_rad >= 1e-4 && step_rad <= 0.05),
                "the grid step must be 0 (automatic) or lie in [1e-4, 0.05] rad, got " << step_rad);
  OMNIRIG_CHECK_IN(step_factor, '[', 1, 8, ']');
}

double FinestAngularStep(const CameraModel& camera) {
  const double radius = InscribedRadius(camera) - 1.0;
  OMNIRIG_CHECK(radius > 2.0, "the principal point lies outside the image");
  const double u0 = camera.intrinsics.u0(), v0 = camera.intrinsics.v0();
  double finest = M_PI;
  constexpr int kSamples = 720;
  for (int k = 0; k < kSamples; ++k) {
    const double a = 2.0 * M_PI * k / kSamples;
    const Eigen::Vector2d radial(std::cos(a), std::sin(a));
    const Eigen::Vector2d tangential(-radial.y(), radial.x());
    for (double r = radius; r > 0.5 * radius; r -= 0.05 * radius) {
      const Eigen::Vector2d p(u0 + r * radial.x(), v0 + r * radial.y());
      const auto b = Lift(camera.intrinsics, p);
      const auto b_radial = Lift(camera.intrinsics, p - radial);
      const auto b_tangential = Lift(camera.intrinsics, p + tangential);
      if (!b || !b_radial || !b_tangential) continue;  // outside the lifting domain: go inwards
      finest = std::min({finest, AngleBetween(*b, *b_radial), AngleBetween(*b, *b_tangential)});
      break;
    }
  }
  OMNIRIG_CHECK(finest < M_PI, "no pixel of the image lifts to a bearing");
  return finest;
}

SphericalRectifier::SphericalRectifier(const StereoRig& rig, const SphericalGridOptions& options) {
  options.Check();
  rig.cam0.intrinsics.Check();
  rig.cam1.intrinsics.Check();
  const Eigen::Vector3d c1_in_cam0 = rig.cam0_from_cam1.translation;
  baseline_m_ = c1_in_cam0.norm();
  OMNIRIG_CHECK(baseline_m_ > 0.0, "the rig's baseline is zero");
  const Eigen::Vector3d pole = c1_in_cam0 / baseline_m_;
  cam0_from_grid_ = FrameAroundPole(pole);

  theta_step_rad_ = options.step_rad > 0.0
                        ? options.step_rad
                        : options.step_factor *
                              std::min(FinestAngularStep(rig.cam0), FinestAngularStep(rig.cam1));
  rows_ = static_cast<int>(std::ceil(2.0 * M_PI / theta_step_rad_));
  const auto [theta_lo, theta_hi] = ThetaRange(rig, pole, theta_step_rad_);
  theta_max_rad_ = theta_hi;
  cols_ = static_cast<int>(std::ceil((theta_hi - theta_lo) / theta_step_rad_)) + 1;

  const Eigen::Matrix3d cam1_from_cam0 = rig.cam0_from_cam1.rotation.conjugate().toRotationMatrix();
  for (int camera = 0; camera < 2; ++camera) {
    const CameraModel& model = camera == 0 ? rig.cam0 : rig.cam1;
    const Eigen::Matrix3d cam_from_grid =
        camera == 0 ? cam0_from_grid_ : Eigen::Matrix3d(cam1_from_cam0 * cam0_from_grid_);
    cv::Mat map_x(rows_, cols_, CV_32F), map_y(rows_, cols_, CV_32F);
    valid_[camera] = cv::Mat::zeros(rows_, cols_, CV_8U);
    cv::parallel_for_(cv::Range(0, rows_), [&](const cv::Range& range) {
      for (int r = range.start; r < range.end; ++r) {
        const double phi = Phi(r);
        const double cos_phi = std::cos(phi), sin_phi = std::sin(phi);
        float* mx = map_x.ptr<float>(r);
        float* my = map_y.ptr<float>(r);
        uint8_t* ok = valid_[camera].ptr<uint8_t>(r);
        for (int c = 0; c < cols_; ++c) {
          const double theta = Theta(c);
          const Eigen::Vector3d in_grid(std::sin(theta) * cos_phi, std::sin(theta) * sin_phi,
                                        std::cos(theta));
          const std::optional<Eigen::Vector2d> pixel =
              Project(model.intrinsics, cam_from_grid * in_grid);
          const bool inside = pixel && pixel->x() >= 0.0 && pixel->y() >= 0.0 &&
                              pixel->x() <= model.width - 1.0 && pixel->y() <= model.height - 1.0;
          mx[c] = inside ? static_cast<float>(pixel->x()) : -1.f;
          my[c] = inside ? static_cast<float>(pixel->y()) : -1.f;
          ok[c] = inside ? 255 : 0;
        }
      }
    });
    cv::convertMaps(map_x, map_y, map_xy_[camera], map_fraction_[camera], CV_16SC2);
  }
}

cv::Mat SphericalRectifier::Rectify(const cv::Mat& image, int camera) const {
  OMNIRIG_CHECK(camera == 0 || camera == 1, "camera must be 0 or 1, got " << camera);
  cv::Mat out;
  cv::remap(image, out, map_xy_[camera], map_fraction_[camera], cv::INTER_LINEAR,
            cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return out;
}

namespace {
// Every number the tables depend on.
std::vector<double> RectifierKey(const StereoRig& rig, const SphericalGridOptions& options) {
  std::vector<double> key;
  for (const CameraModel* camera : {&rig.cam0, &rig.cam1}) {
    key.insert(key.end(), camera->intrinsics.params.begin(), camera->intrinsics.params.end());
    key.push_back(camera->width);
    key.push_back(camera->height);
  }
  const Eigen::Quaterniond& q = rig.cam0_from_cam1.rotation;
  const Eigen::Vector3d& t = rig.cam0_from_cam1.translation;
  key.insert(key.end(), {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()});
  key.insert(key.end(), {options.step_rad, options.step_factor});
  return key;
}
}  // namespace

namespace {

// The tables file's format: bump kTablesVersion whenever it, or what the tables hold for a given
// rig and options, changes (a new version is a new file name, so old files are never read).
constexpr char kTablesMagic[] = "omnirig-rectification\n";
constexpr uint32_t kTablesVersion = 1;

// FNV-1a over the key's bytes (the file name's hash; the file holds the whole key, compared on
// reading, so a collision costs a rebuild, never wrong tables).
uint64_t KeyHash(const std::vector<double>& key) {
  uint64_t hash = 1469598103934665603ull;
  const auto* bytes = reinterpret_cast<const unsigned char*>(key.data());
  for (size_t i = 0; i < key.size() * sizeof(double); ++i) {
    hash = (hash ^ bytes[i]) * 1099511628211ull;
  }
  return hash;
}

// The tables of one camera in file order, with their element sizes.
std::vector<cv::Mat*> TableMats(cv::Mat (&map_xy)[2], cv::Mat (&map_fraction)[2],
                                cv::Mat (&valid)[2]) {
  return {&map_xy[0], &map_fraction[0], &valid[0], &map_xy[1], &map_fraction[1], &valid[1]};
}
constexpr int kTableTypes[6] = {CV_16SC2, CV_16UC1, CV_8UC1, CV_16SC2, CV_16UC1, CV_8UC1};

template <typename T>
bool ReadValue(std::istream& in, T* value) {
  return static_cast<bool>(in.read(reinterpret_cast<char*>(value), sizeof(T)));
}

template <typename T>
void WriteValue(std::FILE* file, const T& value, bool* ok) {
  *ok = *ok && std::fwrite(&value, sizeof(T), 1, file) == 1;
}

}  // namespace

std::string RectificationTablesFileName(const StereoRig& rig, const SphericalGridOptions& options) {
  char hash[17];
  std::snprintf(hash, sizeof(hash), "%016llx",
                static_cast<unsigned long long>(KeyHash(RectifierKey(rig, options))));
  return "rectification-v" + std::to_string(kTablesVersion) + "-" + hash + ".bin";
}

std::shared_ptr<const SphericalRectifier> SphericalRectifier::Read(
    const std::filesystem::path& path, const std::vector<double>& key) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return nullptr;
  char magic[sizeof(kTablesMagic) - 1];
  uint32_t version = 0;
  uint64_t key_size = 0;
  if (!in.read(magic, sizeof(magic)) || std::memcmp(magic, kTablesMagic, sizeof(magic)) != 0 ||
      !ReadValue(in, &version) || version != kTablesVersion || !ReadValue(in, &key_size) ||
      key_size != key.size()) {
    return nullptr;
  }
  std::vector<double> stored(key_size);
  if (!in.read(reinterpret_cast<char*>(stored.data()), key_size * sizeof(double)) ||
      stored != key) {
    return nullptr;
  }
  auto rectifier = std::shared_ptr<SphericalRectifier>(new SphericalRectifier());
  SphericalRectifier& r = *rectifier;
  if (!ReadValue(in, &r.rows_) || !ReadValue(in, &r.cols_) || !ReadValue(in, &r.theta_step_rad_) ||
      !ReadValue(in, &r.theta_max_rad_) || !ReadValue(in, &r.baseline_m_) ||
      !in.read(reinterpret_cast<char*>(r.cam0_from_grid_.data()), 9 * sizeof(double)) ||
      r.rows_ <= 0 || r.cols_ <= 0 || r.rows_ > 100000 || r.cols_ > 100000) {
    return nullptr;
  }
  const std::vector<cv::Mat*> mats = TableMats(r.map_xy_, r.map_fraction_, r.valid_);
  for (size_t i = 0; i < mats.size(); ++i) {
    mats[i]->create(r.rows_, r.cols_, kTableTypes[i]);
    if (!in.read(reinterpret_cast<char*>(mats[i]->data),
                 static_cast<std::streamsize>(mats[i]->total() * mats[i]->elemSize()))) {
      return nullptr;
    }
  }
  if (in.peek() != std::char_traits<char>::eof()) return nullptr;  // not this format after all
  return rectifier;
}

void SphericalRectifier::Write(const std::filesystem::path& path,
                               const std::vector<double>& key) const {
  // A hidden ".part-" name: the service's start-up check removes what a crash leaves.
  static std::atomic<int> counter{0};
  const std::filesystem::path temp =
      path.parent_path() / ("." + path.filename().string() + ".part-" + std::to_string(::getpid()) +
                            "-" + std::to_string(counter++));
  std::error_code error;
  std::filesystem::create_directories(path.parent_path(), error);
  std::FILE* file = std::fopen(temp.c_str(), "wb");
  if (!file) return;
  bool ok = std::fwrite(kTablesMagic, sizeof(kTablesMagic) - 1, 1, file) == 1;
  WriteValue(file, kTablesVersion, &ok);
  WriteValue(file, static_cast<uint64_t>(key.size()), &ok);
  ok = ok && std::fwrite(key.data(), sizeof(double), key.size(), file) == key.size();
  WriteValue(file, rows_, &ok);
  WriteValue(file, cols_, &ok);
  WriteValue(file, theta_step_rad_, &ok);
  WriteValue(file, theta_max_rad_, &ok);
  WriteValue(file, baseline_m_, &ok);
  ok = ok && std::fwrite(cam0_from_grid_.data(), sizeof(double), 9, file) == 9;
  cv::Mat map_xy[2] = {map_xy_[0], map_xy_[1]}, fraction[2] = {map_fraction_[0], map_fraction_[1]},
          valid[2] = {valid_[0], valid_[1]};
  for (cv::Mat* mat : TableMats(map_xy, fraction, valid)) {
    const cv::Mat continuous = mat->isContinuous() ? *mat : mat->clone();
    const size_t bytes = continuous.total() * continuous.elemSize();
    ok = ok && std::fwrite(continuous.data, 1, bytes, file) == bytes;
  }
  ok = ok && std::fflush(file) == 0 && ::fsync(fileno(file)) == 0;
  ok = std::fclose(file) == 0 && ok;
  if (ok) std::filesystem::rename(temp, path, error);
  if (!ok || error) std::filesystem::remove(temp, error);
}

int PruneRectificationTables(const std::filesystem::path& dir, uintmax_t max_bytes) {
  struct Entry {
    std::filesystem::file_time_type used;
    uintmax_t bytes;
    std::filesystem::path path;
  };
  std::vector<Entry> files;
  std::error_code error;
  for (std::filesystem::directory_iterator it(dir, error), end; !error && it != end;
       it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("rectification-v", 0) != 0 || it->path().extension() != ".bin") continue;
    std::error_code file_error;
    const uintmax_t bytes = it->file_size(file_error);
    const std::filesystem::file_time_type used = it->last_write_time(file_error);
    if (!file_error) files.push_back({used, bytes, it->path()});
  }
  std::sort(files.begin(), files.end(),
            [](const Entry& a, const Entry& b) { return a.used > b.used; });
  int removed = 0;
  uintmax_t kept_bytes = 0;
  for (size_t i = 0; i < files.size(); ++i) {
    kept_bytes += files[i].bytes;
    if (i == 0 || kept_bytes <= max_bytes) continue;
    kept_bytes -= files[i].bytes;
    std::error_code remove_error;
    removed += std::filesystem::remove(files[i].path, remove_error) ? 1 : 0;
  }
  return removed;
}

std::shared_ptr<const SphericalRectifier> SharedRectifier(const StereoRig& rig,
                                                          const SphericalGridOptions& options,
                                                          const std::filesystem::path& tables_dir) {
  constexpr size_t kKept = 2;
  using Entry = std::pair<std::vector<double>, std::shared_ptr<const SphericalRectifier>>;
  static std::mutex mutex;
  static std::list<Entry> cache;  // most recently used first
  const std::vector<double> key = RectifierKey(rig, options);
  // Held while building (up to a second): a second job of the same rig waits for the tables
  // instead of building them again; one of another rig waits too, which is rare and short.
  std::lock_guard<std::mutex> lock(mutex);
  const std::filesystem::path file = tables_dir.empty()
                                         ? std::filesystem::path()
                                         : tables_dir / RectificationTablesFileName(rig, options);
  for (auto it = cache.begin(); it != cache.end(); ++it) {
    if (it->first != key) continue;
    cache.splice(cache.begin(), cache, it);
    // Built in this process without a folder, or the file removed since: written now.
    std::error_code error;
    if (!file.empty() && !std::filesystem::exists(file, error)) {
      it->second->Write(file, key);
      PruneRectificationTables(tables_dir, kRectificationTablesMaxBytes);
    } else if (!file.empty()) {
      std::filesystem::last_write_time(file, std::filesystem::file_time_type::clock::now(), error);
    }
    return cache.front().second;
  }
  std::shared_ptr<const SphericalRectifier> rectifier;
  if (!file.empty()) rectifier = SphericalRectifier::Read(file, key);
  std::error_code error;
  if (rectifier) {
    // Used now: the last to be pruned (PruneRectificationTables orders by this time).
    std::filesystem::last_write_time(file, std::filesystem::file_time_type::clock::now(), error);
  } else {
    rectifier = std::make_shared<const SphericalRectifier>(rig, options);
    if (!file.empty()) {
      rectifier->Write(file, key);
      PruneRectificationTables(tables_dir, kRectificationTablesMaxBytes);
    }
  }
  cache.emplace_front(key, rectifier);
  if (cache.size() > kKept) cache.pop_back();
  return rectifier;
}

}  // namespace omnirig::dense
