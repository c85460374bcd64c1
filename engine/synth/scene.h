#pragma once
// Scenes for the synthetic renderer: a planar checkerboard with a white margin, and textured
// planes, boxes and cylinders whose procedural textures are rich in corners and blobs at several
// scales (for feature matching). Everything is deterministic given the texture seeds.
//
// Local frames of the primitives (world_from_local places them in the world, metres):
//   checkerboard  the board frame: inner corner (c, r) at (c * square, r * square, 0), x along
//                 the columns, y along the rows. The squares cover [-square, cols * square] x
//                 [-square, rows * square]; the white margin extends margin_m beyond them. The
//                 pattern is printed on the side facing the board's -z (a camera at negative
//                 board z sees it, as with OpenCV's board convention); the back is plain grey.
//                 The square at (-1, -1) (board's top-left corner) is black.
//   plane         the rectangle |x| <= size_x / 2, |y| <= size_y / 2 of z = 0, seen from both
//                 sides.
//   box           the axis-aligned box |x| <= size.x / 2, |y| <= size.y / 2, |z| <= size.z / 2.
//   cylinder      x^2 + y^2 = radius^2 for 0 <= z <= height, with both end caps.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/rigid3.h"

namespace omnirig::synth {

struct CheckerboardSpec {
  int cols = 8;  // inner corners along the board's x axis
  int rows = 6;  // inner corners along the board's y axis
  double square_size_m = 0.04;
  double margin_m = 0.03;  // white border beyond the outer squares

  // Throws InvalidArgument unless cols, rows >= 2 and the sizes are positive (margin >= 0).
  void Check() const;
  double width_m() const { return (cols + 1) * square_size_m + 2 * margin_m; }
  double height_m() const { return (rows + 1) * square_size_m + 2 * margin_m; }
};

// The inner corners in the board frame (z = 0), row-major (index r * cols + c), metres.
std::vector<Eigen::Vector3d> BoardCorners(const CheckerboardSpec& spec);

// The board's outer outline (margin included) in the board frame, counter-clockwise from the
// top-left corner: (x_min, y_min), (x_max, y_min), (x_max, y_max), (x_min, y_max), z = 0.
std::vector<Eigen::Vector3d> BoardOutline(const CheckerboardSpec& spec);

// A procedural texture: grey-level value noise at several scales plus random rectangles,
// rotated rectangles and discs, tinted by color_rgb.
struct TextureSpec {
  enum class Style {
    kRich,   // noise + many high-contrast shapes: good for feature matching
    kSoft,   // low-contrast noise only: backgrounds that must not distract a board detector
    kPlain,  // uniform grey
  };
  Style style = Style::kRich;
  uint64_t seed = 0;
  Eigen::Vector3d color_rgb{1.0, 1.0, 1.0};  // multiplies the grey level, components in [0, 1]
  double texel_size_m = 0.005;               // coarsened when a face would exceed 2048 texels
  double shapes_per_m2 = 40.0;               // density of rectangles and discs (kRich)
};

// A primitive as written to ground truth. size_m: board (width, height, 0) with the margin;
// plane (size_x, size_y, 0); box (size_x, size_y, size_z); cylinder (radius, radius, height).
struct PrimitiveInfo {
  enum class Kind { kCheckerboard, kPlane, kBox, kCylinder };
  Kind kind = Kind::kPlane;
  std::string name;
  Rigid3d world_from_local;
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();
  TextureSpec texture;                    // unused for checkerboards
  std::optional<CheckerboardSpec> board;  // set for checkerboards
};
const char* KindName(PrimitiveInfo::Kind kind);  // "checkerboard", "plane", "box", "cylinder"

class Scene {
 public:
  // Each Add* returns the primitive's index in primitives(). Textures are generated here (a few
  // milliseconds per square metre), so that rendering only samples them.
  int AddCheckerboard(const CheckerboardSpec& spec, const Rigid3d& world_from_board,
                      const std::string& name = "board");
  int AddPlane(const Rigid3d& world_from_plane, double size_x_m, double size_y_m,
               const TextureSpec& texture, const std::string& name = "plane");
  int AddBox(const Rigid3d& world_from_box, const Eigen::Vector3d& size_m,
             const TextureSpec& texture, const std::string& name = "box");
  int AddCylinder(const Rigid3d& world_from_cylinder, double radius_m, double height_m,
                  const TextureSpec& texture, const std::string& name = "cylinder");

  // Moves an existing checkerboard (cheap: for rendering many views of one board).
  void SetBoardPose(int index, const Rigid3d& world_from_board);

  // The colour of rays that hit nothing (sky), RGB in [0, 1].
  void SetBackgroundRgb(const Eigen::Vector3d& rgb) { background_rgb_ = rgb; }
  const Eigen::Vector3d& background_rgb() const { return background_rgb_; }

  const std::vector<PrimitiveInfo>& primitives() const { return primitives_; }

  // Grey textures (CV_8UC1) of primitive `index`, one per face: plane 1; box 6 (+x, -x, +y, -y,
  // +z, -z, texel (col, row) = the two remaining local axes in order, from their minimum);
  // cylinder 3 (side: col = angle * radius from the +x axis towards +y, row = z; then the caps
  // at z = 0 and z = height: col = x, row = y from -radius); checkerboard none. Texel size is
  // extent / texture size along each axis.
  const std::vector<std::shared_ptr<const cv::Mat>>& textures(int index) const {
    return textures_.at(index);
  }

 private:
  using Textures = std::vector<std::shared_ptr<const cv::Mat>>;
  // Appends a primitive with its textures (none for a checkerboard); returns its index.
  int Add(PrimitiveInfo::Kind kind, const std::string& name, const Rigid3d& world_from_local,
          const Eigen::Vector3d& size_m, const TextureSpec& texture, Textures textures);

  std::vector<PrimitiveInfo> primitives_;
  std::vector<std::vector<std::shared_ptr<const cv::Mat>>> textures_;
  Eigen::Vector3d background_rgb_{0.55, 0.65, 0.8};
};

// The local axes along a box face's texture columns and rows, for the faces normal to `axis`
// (0 = x, 1 = y, 2 = z): the two remaining axes in increasing order.
inline std::array<int, 2> BoxFaceAxes(int axis) {
  return axis == 0 ? std::array<int, 2>{1, 2}
                   : (axis == 1 ? std::array<int, 2>{0, 2} : std::array<int, 2>{0, 1});
}

// Derives an independent seed from (seed, salt) (SplitMix64): for faces, views and layers.
uint64_t DeriveSeed(uint64_t seed, uint64_t salt);

// The presets' textures: kRich, its seed derived from (seed, salt), tinted by `rgb`; the
// defaults are TextureSpec's.
TextureSpec RichTexture(uint64_t seed, uint64_t salt, const Eigen::Vector3d& rgb,
                        double shapes_per_m2 = 40.0, double texel_size_m = 0.005);

// A texture of the given spec covering extent_x_m x extent_y_m (CV_8UC1).
cv::Mat MakeTexture(const TextureSpec& spec, double extent_x_m, double extent_y_m);

}  // namespace omnirig::synth
