#include "engine/synth/scene.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig::synth {
namespace {

constexpr int kMaxTextureSide = 2048;
constexpr int kMaxShapes = 20000;

// Value noise: the sum of uniform random grids with cells of cell_m metres, upsampled
// bicubically. Returns values roughly in [0, 1].
cv::Mat ValueNoise(int cols, int rows, double texel_m, uint64_t seed) {
  cv::Mat noise(rows, cols, CV_32F, cv::Scalar(0.0));
  const double cells_m[] = {0.5, 0.12, 0.03};
  const double weights[] = {0.5, 0.3, 0.2};
  double total_weight = 0.0;
  for (int octave = 0; octave < 3; ++octave) {
    const double cells_per_texel = texel_m / cells_m[octave];
    if (cells_per_texel > 0.5) continue;  // finer than the texture can hold
    const int small_cols = std::max(2, static_cast<int>(std::ceil(cols * cells_per_texel)) + 1);
    const int small_rows = std::max(2, static_cast<int>(std::ceil(rows * cells_per_texel)) + 1);
    cv::Mat small(small_rows, small_cols, CV_32F);
    cv::RNG rng(DeriveSeed(seed, octave));
    rng.fill(small, cv::RNG::UNIFORM, 0.0, 1.0);
    cv::Mat large;
    cv::resize(small, large, cv::Size(cols, rows), 0, 0, cv::INTER_CUBIC);
    noise += weights[octave] * large;
    total_weight += weights[octave];
  }
  if (total_weight > 0.0) noise /= total_weight;
  return noise;
}

// Random filled rectangles (axis-aligned and rotated), discs and rings of log-uniform sizes from
// 2 cm to 30 cm: corners and blobs at several scales for feature detectors.
void DrawShapes(cv::Mat* texture, double texel_m, double area_m2, double shapes_per_m2,
                uint64_t seed) {
  cv::RNG rng(DeriveSeed(seed, 100));
  const int count = std::min(kMaxShapes, static_cast<int>(std::lround(area_m2 * shapes_per_m2)));
  for (int i = 0; i < count; ++i) {
    const double size_m = 0.02 * std::pow(15.0, rng.uniform(0.0, 1.0));
    const double size_px = size_m / texel_m;
    if (size_px < 1.5) continue;
    const cv::Point2f centre(rng.uniform(0.0f, static_cast<float>(texture->cols)),
                             rng.uniform(0.0f, static_cast<float>(texture->rows)));
    // Mostly dark or bright shapes: strong gradients.
    const double grey =
        rng.uniform(0.0, 1.0) < 0.5 ? rng.uniform(10.0, 90.0) : rng.uniform(165.0, 250.0);
    const cv::Scalar colour(grey);
    const int type = rng.uniform(0, 4);
    if (type == 0 || type == 1) {
      const float aspect = static_cast<float>(rng.uniform(0.4, 2.5));
      const float angle = type == 0 ? 0.0f : static_cast<float>(rng.uniform(0.0, 180.0));
      const cv::RotatedRect rect(centre, cv::Size2f(size_px, size_px * aspect), angle);
      cv::Point2f corners_f[4];
      rect.points(corners_f);
      cv::Point corners[4];
      for (int c = 0; c < 4; ++c)
        corners[c] = cv::Point(cvRound(corners_f[c].x), cvRound(corners_f[c].y));
      cv::fillConvexPoly(*texture, corners, 4, colour, cv::LINE_AA);
    } else if (type == 2) {
      cv::circle(*texture, centre, std::max(1, cvRound(size_px / 2)), colour, cv::FILLED,
                 cv::LINE_AA);
    } else {
      const int thickness = std::max(1, cvRound(size_px / 8));
      cv::circle(*texture, centre, std::max(1, cvRound(size_px / 2)), colour, thickness,
                 cv::LINE_AA);
    }
  }
}

}  // namespace

uint64_t DeriveSeed(uint64_t seed, uint64_t salt) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ull * (salt + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

TextureSpec RichTexture(uint64_t seed, uint64_t salt, const Eigen::Vector3d& rgb,
                        double shapes_per_m2, double texel_size_m) {
  TextureSpec spec;
  spec.texel_size_m = texel_size_m;
  spec.style = TextureSpec::Style::kRich;
  spec.seed = DeriveSeed(seed, salt);
  spec.color_rgb = rgb;
  spec.shapes_per_m2 = shapes_per_m2;
  return spec;
}

void CheckerboardSpec::Check() const {
  OMNIRIG_CHECK(cols >= 2 && rows >= 2,
                "a board needs at least 2 x 2 inner corners, got " << cols << " x " << rows);
  OMNIRIG_CHECK_POSITIVE(square_size_m);
  OMNIRIG_CHECK_NON_NEGATIVE(margin_m);
}

std::vector<Eigen::Vector3d> BoardCorners(const CheckerboardSpec& spec) {
  spec.Check();
  std::vector<Eigen::Vector3d> corners;
  corners.reserve(static_cast<size_t>(spec.cols) * spec.rows);
  for (int r = 0; r < spec.rows; ++r) {
    for (int c = 0; c < spec.cols; ++c) {
      corners.emplace_back(c * spec.square_size_m, r * spec.square_size_m, 0.0);
    }
  }
  return corners;
}

std::vector<Eigen::Vector3d> BoardOutline(const CheckerboardSpec& spec) {
  spec.Check();
  const double x_min = -spec.square_size_m - spec.margin_m;
  const double y_min = x_min;
  const double x_max = spec.cols * spec.square_size_m + spec.margin_m;
  const double y_max = spec.rows * spec.square_size_m + spec.margin_m;
  return {{x_min, y_min, 0.0}, {x_max, y_min, 0.0}, {x_max, y_max, 0.0}, {x_min, y_max, 0.0}};
}

const char* KindName(PrimitiveInfo::Kind kind) {
  switch (kind) {
    case PrimitiveInfo::Kind::kCheckerboard:
      return "checkerboard";
    case PrimitiveInfo::Kind::kPlane:
      return "plane";
    case PrimitiveInfo::Kind::kBox:
      return "box";
    case PrimitiveInfo::Kind::kCylinder:
      return "cylinder";
  }
  return "unknown";
}

cv::Mat MakeTexture(const TextureSpec& spec, double extent_x_m, double extent_y_m) {
  OMNIRIG_CHECK_POSITIVE(extent_x_m);
  OMNIRIG_CHECK_POSITIVE(extent_y_m);
  OMNIRIG_CHECK_POSITIVE(spec.texel_size_m);
  const double texel_m =
      std::max(spec.texel_size_m, std::max(extent_x_m, extent_y_m) / kMaxTextureSide);
  const int cols = std::max(2, static_cast<int>(std::ceil(extent_x_m / texel_m)));
  const int rows = std::max(2, static_cast<int>(std::ceil(extent_y_m / texel_m)));
  if (spec.style == TextureSpec::Style::kPlain) return cv::Mat(rows, cols, CV_8U, cv::Scalar(160));
  const cv::Mat noise = ValueNoise(cols, rows, texel_m, spec.seed);
  cv::Mat texture;
  if (spec.style == TextureSpec::Style::kSoft) {
    noise.convertTo(texture, CV_8U, 70.0, 125.0);  // grey levels ~ 125 .. 195
    return texture;
  }
  noise.convertTo(texture, CV_8U, 200.0, 25.0);
  DrawShapes(&texture, texel_m, extent_x_m * extent_y_m, spec.shapes_per_m2, spec.seed);
  return texture;
}

int Scene::Add(PrimitiveInfo::Kind kind, const std::string& name, const Rigid3d& world_from_local,
               const Eigen::Vector3d& size_m, const TextureSpec& texture, Textures textures) {
  PrimitiveInfo info;
  info.kind = kind;
  info.name = name;
  info.world_from_local = world_from_local;
  info.size_m = size_m;
  info.texture = texture;
  primitives_.push_back(info);
  textures_.push_back(std::move(textures));
  return static_cast<int>(primitives_.size()) - 1;
}

int Scene::AddCheckerboard(const CheckerboardSpec& spec, const Rigid3d& world_from_board,
                           const std::string& name) {
  spec.Check();
  const int index = Add(PrimitiveInfo::Kind::kCheckerboard, name, world_from_board,
                        Eigen::Vector3d(spec.width_m(), spec.height_m(), 0.0), TextureSpec(), {});
  primitives_[index].board = spec;
  return index;
}

void Scene::SetBoardPose(int index, const Rigid3d& world_from_board) {
  OMNIRIG_CHECK(index >= 0 && index < static_cast<int>(primitives_.size()) &&
                    primitives_[index].kind == PrimitiveInfo::Kind::kCheckerboard,
                "primitive " << index << " is not a checkerboard");
  primitives_[index].world_from_local = world_from_board;
}

int Scene::AddPlane(const Rigid3d& world_from_plane, double size_x_m, double size_y_m,
                    const TextureSpec& texture, const std::string& name) {
  OMNIRIG_CHECK_POSITIVE(size_x_m);
  OMNIRIG_CHECK_POSITIVE(size_y_m);
  return Add(PrimitiveInfo::Kind::kPlane, name, world_from_plane,
             Eigen::Vector3d(size_x_m, size_y_m, 0.0), texture,
             {std::make_shared<const cv::Mat>(MakeTexture(texture, size_x_m, size_y_m))});
}

int Scene::AddBox(const Rigid3d& world_from_box, const Eigen::Vector3d& size_m,
                  const TextureSpec& texture, const std::string& name) {
  for (int k = 0; k < 3; ++k) OMNIRIG_CHECK_POSITIVE(size_m[k]);
  Textures faces;
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2;
    TextureSpec face_spec = texture;
    face_spec.seed = DeriveSeed(texture.seed, 10 + face);
    const std::array<int, 2> axes = BoxFaceAxes(axis);
    faces.push_back(
        std::make_shared<const cv::Mat>(MakeTexture(face_spec, size_m[axes[0]], size_m[axes[1]])));
  }
  return Add(PrimitiveInfo::Kind::kBox, name, world_from_box, size_m, texture, std::move(faces));
}

int Scene::AddCylinder(const Rigid3d& world_from_cylinder, double radius_m, double height_m,
                       const TextureSpec& texture, const std::string& name) {
  OMNIRIG_CHECK_POSITIVE(radius_m);
  OMNIRIG_CHECK_POSITIVE(height_m);
  Textures faces;
  faces.push_back(
      std::make_shared<const cv::Mat>(MakeTexture(texture, 2.0 * M_PI * radius_m, height_m)));
  for (int cap = 0; cap < 2; ++cap) {
    TextureSpec cap_spec = texture;
    cap_spec.seed = DeriveSeed(texture.seed, 20 + cap);
    faces.push_back(
        std::make_shared<const cv::Mat>(MakeTexture(cap_spec, 2.0 * radius_m, 2.0 * radius_m)));
  }
  return Add(PrimitiveInfo::Kind::kCylinder, name, world_from_cylinder,
             Eigen::Vector3d(radius_m, radius_m, height_m), texture, std::move(faces));
}

}  // namespace omnirig::synth
