#include "engine/synth/render.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"
#include "engine/util/option_check.h"
#include "engine/util/parallel.h"

namespace omnirig::synth {
namespace {

constexpr double kMinHitDistance = 1e-9;
constexpr double kHalfPixelDiagonal = 0.7072;
constexpr double kBoardBackLevel = 110.0;
constexpr int kMaxFaces = 6;
constexpr int kTilePixels = 16;  // side of the tiles of ray-primitive culling

enum PixelClass : uint8_t { kDark = 0, kInside = 1, kBorder = 2 };

int ResolveThreads(int num_threads, int rows) {
  int threads =
      num_threads > 0 ? num_threads : static_cast<int>(std::thread::hardware_concurrency());
  return std::clamp(threads, 1, std::max(1, rows));
}

// Runs body(row) for every row in [0, rows) on `threads` threads.
void ParallelRows(int rows, int threads, const std::function<void(int)>& body) {
  RunTasks(
      rows, threads, ProgressSink{}, [&body](int row, const ProgressSink&) { body(row); }, nullptr);
}

// The normalised plane as the image of a camera with K = I and no distortion: lifting one of
// its points through the camera model is eq. (6) alone, with the model's valid domain.
UnifiedIntrinsics NormalisedPlane(double xi) {
  UnifiedIntrinsics plane;
  plane.xi() = xi;
  return plane;
}

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  int primitive = -1;
  int face = 0;
  double u = 0.0, v = 0.0;  // face coordinates, metres
};

struct FaceTexture {
  const cv::Mat* image = nullptr;
  double texels_per_m_u = 0.0, texels_per_m_v = 0.0;
  Eigen::Vector3f rgb = Eigen::Vector3f::Ones();  // the primitive's tint under the lighting
};

// A primitive expressed for one frame: rays leave the camera centre, so only the camera's
// position and orientation in the primitive's local frame are needed.
struct FramePrimitive {
  PrimitiveInfo::Kind kind = PrimitiveInfo::Kind::kPlane;
  Eigen::Matrix3d local_from_cam = Eigen::Matrix3d::Identity();
  Eigen::Vector3d origin_in_local = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_size = Eigen::Vector3d::Zero();  // cylinder: (radius, radius, height)
  // Checkerboard only.
  double square_m = 0.0, x_min = 0.0, y_min = 0.0, x_max = 0.0, y_max = 0.0;
  int cols = 0, rows = 0;
  std::array<FaceTexture, kMaxFaces> faces;
  // Bounding sphere in the camera frame, to skip primitives a ray cannot reach.
  Eigen::Vector3d bound_centre_in_cam = Eigen::Vector3d::Zero();
  double bound_radius2 = 0.0;
  bool camera_inside_bound = true;
};

// The bounding sphere (centre in the local frame, radius) of a primitive.
std::pair<Eigen::Vector3d, double> LocalBound(const PrimitiveInfo& info) {
  const Eigen::Vector3d& size = info.size_m;
  switch (info.kind) {
    case PrimitiveInfo::Kind::kCheckerboard: {
      const auto outline = BoardOutline(*info.board);
      return {0.5 * (outline[0] + outline[2]), 0.5 * (outline[2] - outline[0]).norm()};
    }
    case PrimitiveInfo::Kind::kPlane:
    case PrimitiveInfo::Kind::kBox:
      return {Eigen::Vector3d::Zero(), 0.5 * size.norm()};
    case PrimitiveInfo::Kind::kCylinder:
      return {Eigen::Vector3d(0, 0, 0.5 * size.z()), std::hypot(size.x(), 0.5 * size.z())};
  }
  return {Eigen::Vector3d::Zero(), std::numeric_limits<double>::infinity()};
}

// The lighting's factor for a surface of unit normal `normal` (on the side the camera sees),
// both in the same frame as `sun`. Exactly 1 for the default lighting.
double LightFactor(const Lighting& lighting, const Eigen::Vector3d& normal,
                   const Eigen::Vector3d& sun) {
  return (1.0 - lighting.sun_share) + 2.0 * lighting.sun_share * std::max(0.0, normal.dot(sun));
}

// The lit colour of each face of a textured primitive (face order of Scene::textures()).
std::array<Eigen::Vector3f, kMaxFaces> LitFaceColours(const PrimitiveInfo& info,
                                                       const Eigen::Vector3d& origin_in_local,
                                                       const Lighting& lighting) {
  const Eigen::Vector3d sun_in_local =
      info.world_from_local.rotation.inverse() * lighting.sun_in_world.normalized();
  std::array<double, kMaxFaces> factors;
  factors.fill(1.0);
  const Eigen::Vector3d half = 0.5 * info.size_m;
  if (info.kind == PrimitiveInfo::Kind::kBox) {
    // From inside (a room) the walls' inner sides face the camera.
    const bool inside = (origin_in_local.cwiseAbs() - half).maxCoeff() < 0.0;
    for (int face = 0; face < 6; ++face) {
      Eigen::Vector3d normal = Eigen::Vector3d::Zero();
      normal[face / 2] = (face % 2 == 0) == !inside ? 1.0 : -1.0;
      factors[face] = LightFactor(lighting, normal, sun_in_local);
    }
  } else if (info.kind == PrimitiveInfo::Kind::kPlane) {
    factors[0] = LightFactor(lighting, Eigen::Vector3d(0, 0, origin_in_local.z() >= 0 ? 1 : -1),
                             sun_in_local);
  } else if (info.kind == PrimitiveInfo::Kind::kCylinder) {
    const double mean_side = 2.0 * sun_in_local.head<2>().norm() / M_PI;
    factors[0] = (1.0 - lighting.sun_share) + lighting.sun_share * mean_side;
    factors[1] = LightFactor(lighting, -Eigen::Vector3d::UnitZ(), sun_in_local);
    factors[2] = LightFactor(lighting, Eigen::Vector3d::UnitZ(), sun_in_local);
  }
  std::array<Eigen::Vector3f, kMaxFaces> colours;
  const Eigen::Vector3d global = lighting.gain * lighting.tint_rgb;
  for (int face = 0; face < kMaxFaces; ++face) {
    colours[face] = info.texture.color_rgb.cwiseProduct(global * factors[face]).cast<float>();
  }
  return colours;
}

FramePrimitive MakeFramePrimitive(const Scene& scene, int index, const Rigid3d& cam_from_world,
                                  const Lighting& lighting) {
  const PrimitiveInfo& info = scene.primitives()[index];
  FramePrimitive prim;
  prim.kind = info.kind;
  const Rigid3d local_from_cam = (cam_from_world * info.world_from_local).Inverse();
  prim.local_from_cam = local_from_cam.RotationMatrix();
  prim.origin_in_local = local_from_cam.translation;
  prim.half_size = 0.5 * info.size_m;
  const auto [bound_centre, bound_radius] = LocalBound(info);
  prim.bound_centre_in_cam = local_from_cam.Inverse() * bound_centre;
  prim.bound_radius2 = bound_radius * bound_radius * (1.0 + 1e-9);
  prim.camera_inside_bound = prim.bound_centre_in_cam.squaredNorm() <= prim.bound_radius2;
  if (info.kind == PrimitiveInfo::Kind::kCheckerboard) {
    const auto outline = BoardOutline(*info.board);
    prim.square_m = info.board->square_size_m;
    prim.cols = info.board->cols;
    prim.rows = info.board->rows;
    prim.x_min = outline[0].x();
    prim.y_min = outline[0].y();
    prim.x_max = outline[2].x();
    prim.y_max = outline[2].y();
    return prim;
  }
  if (info.kind == PrimitiveInfo::Kind::kCylinder) {
    prim.half_size = Eigen::Vector3d(info.size_m.x(), info.size_m.x(), info.size_m.z());
  }
  const auto colours = LitFaceColours(info, prim.origin_in_local, lighting);
  for (int face = 0; face < kMaxFaces; ++face) prim.faces[face].rgb = colours[face];
  const auto& textures = scene.textures(index);
  for (size_t face = 0; face < textures.size() && face < kMaxFaces; ++face) {
    double extent_u = info.size_m.x(), extent_v = info.size_m.y();
    if (info.kind == PrimitiveInfo::Kind::kBox) {
      const auto axes = BoxFaceAxes(static_cast<int>(face) / 2);
      extent_u = info.size_m[axes[0]];
      extent_v = info.size_m[axes[1]];
    } else if (info.kind == PrimitiveInfo::Kind::kCylinder) {
      const double r = info.size_m.x();
      extent_u = face == 0 ? 2.0 * M_PI * r : 2.0 * r;
      extent_v = face == 0 ? info.size_m.z() : 2.0 * r;
    }
    prim.faces[face].image = textures[face].get();
    prim.faces[face].texels_per_m_u = textures[face]->cols / extent_u;
    prim.faces[face].texels_per_m_v = textures[face]->rows / extent_v;
  }
  return prim;
}

// Records a hit at distance t if it is nearer than the current one.
inline bool Accept(double t, const Hit& hit) { return t > kMinHitDistance && t < hit.t; }

inline bool IntersectPlanar(const FramePrimitive& prim, const Eigen::Vector3d& o,
                            const Eigen::Vector3d& d, int index, Hit* hit) {
  if (std::abs(d.z()) < 1e-15) return false;
  const double t = -o.z() / d.z();
  if (!Accept(t, *hit)) return false;
  const double x = o.x() + t * d.x(), y = o.y() + t * d.y();
  if (prim.kind == PrimitiveInfo::Kind::kCheckerboard) {
    if (x < prim.x_min || x > prim.x_max || y < prim.y_min || y > prim.y_max) return false;
    *hit = Hit{t, index, d.z() > 0.0 ? 0 : 1, x, y};  // face 0: the printed (-z) side
    return true;
  }
  if (std::abs(x) > prim.half_size.x() || std::abs(y) > prim.half_size.y()) return false;
  *hit = Hit{t, index, 0, x + prim.half_size.x(), y + prim.half_size.y()};
  return true;
}

// Slab test; from inside the box (a room) the exit face is the hit.
bool IntersectBox(const FramePrimitive& prim, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                  int index, Hit* hit) {
  double t_near = -std::numeric_limits<double>::infinity();
  double t_far = std::numeric_limits<double>::infinity();
  int near_face = -1, far_face = -1;
  for (int k = 0; k < 3; ++k) {
    const double h = prim.half_size[k];
    if (std::abs(d[k]) < 1e-15) {
      if (std::abs(o[k]) > h) return false;
      continue;
    }
    const double t_minus = (-h - o[k]) / d[k], t_plus = (h - o[k]) / d[k];
    const bool positive = d[k] > 0.0;
    const double t_in = positive ? t_minus : t_plus, t_out = positive ? t_plus : t_minus;
    if (t_in > t_near) {
      t_near = t_in;
      near_face = 2 * k + (positive ? 1 : 0);
    }
    if (t_out < t_far) {
      t_far = t_out;
      far_face = 2 * k + (positive ? 0 : 1);
    }
  }
  if (t_near > t_far || near_face < 0 || far_face < 0) return false;
  const bool from_outside = t_near > kMinHitDistance;
  const double t = from_outside ? t_near : t_far;
  if (!Accept(t, *hit)) return false;
  const int face = from_outside ? near_face : far_face;
  const auto axes = BoxFaceAxes(face / 2);
  const Eigen::Vector3d p = o + t * d;
  *hit = Hit{t, index, face, p[axes[0]] + prim.half_size[axes[0]],
             p[axes[1]] + prim.half_size[axes[1]]};
  return true;
}

bool IntersectCylinder(const FramePrimitive& prim, const Eigen::Vector3d& o,
                       const Eigen::Vector3d& d, int index, Hit* hit) {
  const double r = prim.half_size.x(), height = prim.half_size.z();
  bool found = false;
  const double a = d.x() * d.x() + d.y() * d.y();
  if (a > 1e-30) {
    const double b = o.x() * d.x() + o.y() * d.y();
    const double c = o.x() * o.x() + o.y() * o.y() - r * r;
    const double disc = b * b - a * c;
    if (disc >= 0.0) {
      const double root = std::sqrt(disc);
      for (const double t : {(-b - root) / a, (-b + root) / a}) {
        const double z = o.z() + t * d.z();
        if (z < 0.0 || z > height || !Accept(t, *hit)) continue;
        double angle = std::atan2(o.y() + t * d.y(), o.x() + t * d.x());
        if (angle < 0.0) angle += 2.0 * M_PI;
        *hit = Hit{t, index, 0, angle * r, z};
        found = true;
        break;
      }
    }
  }
  if (std::abs(d.z()) > 1e-15) {
    for (int cap = 0; cap < 2; ++cap) {
      const double t = ((cap == 0 ? 0.0 : height) - o.z()) / d.z();
      if (!Accept(t, *hit)) continue;
      const double x = o.x() + t * d.x(), y = o.y() + t * d.y();
      if (x * x + y * y > r * r) continue;
      *hit = Hit{t, index, 1 + cap, x + r, y + r};
      found = true;
    }
  }
  return found;
}

inline bool IntersectOne(const FramePrimitive& prim, const Eigen::Vector3d& bearing_in_cam,
                         int index, Hit* hit) {
  const Eigen::Vector3d d = prim.local_from_cam * bearing_in_cam;
  switch (prim.kind) {
    case PrimitiveInfo::Kind::kCheckerboard:
    case PrimitiveInfo::Kind::kPlane:
      return IntersectPlanar(prim, prim.origin_in_local, d, index, hit);
    case PrimitiveInfo::Kind::kBox:
      return IntersectBox(prim, prim.origin_in_local, d, index, hit);
    case PrimitiveInfo::Kind::kCylinder:
      return IntersectCylinder(prim, prim.origin_in_local, d, index, hit);
  }
  return false;
}

// Whether the ray t * d (t > 0) can meet the primitive's bounding sphere before distance best_t.
inline bool MayHit(const FramePrimitive& prim, const Eigen::Vector3d& d, double best_t) {
  if (prim.camera_inside_bound) return true;
  const double cd = prim.bound_centre_in_cam.dot(d);
  if (cd <= 0.0) return false;  // the sphere lies behind the camera
  const double d2 = d.squaredNorm();
  const double miss2 = prim.bound_centre_in_cam.squaredNorm() - cd * cd / d2;
  if (miss2 > prim.bound_radius2) return false;
  return (cd - std::sqrt(prim.bound_radius2 - miss2)) / d2 < best_t;
}

// The nearest hit among `candidates` (indices into prims, in scene order).
Hit IntersectAll(const std::vector<FramePrimitive>& prims, const std::vector<int>& candidates,
                 const Eigen::Vector3d& bearing) {
  Hit hit;
  for (const int i : candidates) {
    if (MayHit(prims[i], bearing, hit.t)) IntersectOne(prims[i], bearing, i, &hit);
  }
  return hit;
}

// A cone of directions from the camera centre: every bearing of a tile of pixels lies within
// half_angle_rad of axis (unit).
struct Cone {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double half_angle_rad = M_PI;
};

// Whether a ray inside `cone` can meet the primitive's bounding sphere. Conservative: when it
// returns false, MayHit() is false for every bearing in the cone.
bool ConeMayHit(const FramePrimitive& prim, const Cone& cone) {
  if (prim.camera_inside_bound || cone.half_angle_rad >= M_PI) return true;
  const double distance = prim.bound_centre_in_cam.norm();
  const double angular_radius = std::asin(std::min(1.0, std::sqrt(prim.bound_radius2) / distance));
  const double angle = std::acos(
      std::clamp(prim.bound_centre_in_cam.dot(cone.axis) / distance, -1.0, 1.0));
  return angle <= cone.half_angle_rad + angular_radius + 1e-6;
}

inline float SampleTexture(const FaceTexture& face, double u, double v) {
  const cv::Mat& image = *face.image;
  const double x = std::clamp(u * face.texels_per_m_u - 0.5, 0.0, image.cols - 1.0);
  const double y = std::clamp(v * face.texels_per_m_v - 0.5, 0.0, image.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), image.cols - 2);
  const int y0 = std::min(static_cast<int>(y), image.rows - 2);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const uint8_t* row0 = image.ptr<uint8_t>(y0) + x0;
  const uint8_t* row1 = image.ptr<uint8_t>(y0 + 1) + x0;
  const float top = row0[0] + fx * (row0[1] - row0[0]);
  const float bottom = row1[0] + fx * (row1[1] - row1[0]);
  return top + fy * (bottom - top);
}

inline Eigen::Vector3f Shade(const std::vector<FramePrimitive>& prims, const Hit& hit,
                             const Eigen::Vector3f& background) {
  if (hit.primitive < 0) return background;
  const FramePrimitive& prim = prims[hit.primitive];
  if (prim.kind == PrimitiveInfo::Kind::kCheckerboard) {
    if (hit.face != 0) return Eigen::Vector3f::Constant(static_cast<float>(kBoardBackLevel));
    const double s = prim.square_m;
    const double x = hit.u, y = hit.v;
    const bool in_squares = x >= -s && x < (prim.cols * s) && y >= -s && y < (prim.rows * s);
    if (!in_squares) return Eigen::Vector3f::Constant(static_cast<float>(kBoardWhiteLevel));
    const long parity = static_cast<long>(std::floor(x / s)) + static_cast<long>(std::floor(y / s));
    const double level = (parity % 2 == 0) ? kBoardBlackLevel : kBoardWhiteLevel;
    return Eigen::Vector3f::Constant(static_cast<float>(level));
  }
  const FaceTexture& face = prim.faces[hit.face];
  if (face.image == nullptr) return face.rgb * 128.0f;
  return face.rgb * SampleTexture(face, hit.u, hit.v);
}

// Exact box filtering of the checker pattern. Over one pixel the map from the image to the
// board plane is affine to within 1e-3 px (the pixel is tiny against the curvature of the
// mirror's mapping), so the pixel's footprint is the quadrilateral of its four corners' board
// points, and its grey level is the black area fraction of that quadrilateral: no sampling
// error at the corners and edges that calibration measures.
struct Polygon {
  std::array<Eigen::Vector2d, 8> v;
  int n = 0;
};

// Sutherland-Hodgman against the half-plane sign * (p[axis] - bound) >= 0.
Polygon ClipAxis(const Polygon& in, int axis, double bound, double sign) {
  Polygon out;
  for (int i = 0; i < in.n; ++i) {
    const Eigen::Vector2d& a = in.v[i];
    const Eigen::Vector2d& b = in.v[(i + 1) % in.n];
    const double da = sign * (a[axis] - bound), db = sign * (b[axis] - bound);
    if (da >= 0.0) out.v[out.n++] = a;
    if ((da >= 0.0) != (db >= 0.0)) out.v[out.n++] = a + (da / (da - db)) * (b - a);
  }
  return out;
}

double Area(const Polygon& polygon) {
  double twice = 0.0;
  for (int i = 0; i < polygon.n; ++i) {
    const Eigen::Vector2d& a = polygon.v[i];
    const Eigen::Vector2d& b = polygon.v[(i + 1) % polygon.n];
    twice += a.x() * b.y() - a.y() * b.x();
  }
  return 0.5 * std::abs(twice);
}

// The board pixel's grey level from its footprint `quad` (board coordinates, in order around
// the pixel); nullopt when the footprint spans too many squares (a far board: sampling is then
// the better estimate).
std::optional<float> BoardPixelLevel(const FramePrimitive& board, const Polygon& quad) {
  const double area = Area(quad);
  if (!(area > 0.0)) return std::nullopt;
  const double s = board.square_m;
  double min_x = quad.v[0].x(), max_x = min_x, min_y = quad.v[0].y(), max_y = min_y;
  for (int i = 1; i < quad.n; ++i) {
    min_x = std::min(min_x, quad.v[i].x());
    max_x = std::max(max_x, quad.v[i].x());
    min_y = std::min(min_y, quad.v[i].y());
    max_y = std::max(max_y, quad.v[i].y());
  }
  const int ix0 = static_cast<int>(std::floor(min_x / s)),
            ix1 = static_cast<int>(std::floor(max_x / s));
  const int iy0 = static_cast<int>(std::floor(min_y / s)),
            iy1 = static_cast<int>(std::floor(max_y / s));
  if ((ix1 - ix0 + 1) * (iy1 - iy0 + 1) > 16) return std::nullopt;
  double black = 0.0;
  for (int iy = std::max(iy0, -1); iy <= std::min(iy1, board.rows - 1); ++iy) {
    for (int ix = std::max(ix0, -1); ix <= std::min(ix1, board.cols - 1); ++ix) {
      if (((ix + iy) & 1) != 0) continue;  // white square; (-1, -1) is black
      Polygon clipped = ClipAxis(quad, 0, ix * s, 1.0);
      clipped = ClipAxis(clipped, 0, (ix + 1) * s, -1.0);
      clipped = ClipAxis(clipped, 1, iy * s, 1.0);
      clipped = ClipAxis(clipped, 1, (iy + 1) * s, -1.0);
      black += Area(clipped);
    }
  }
  const double fraction = std::clamp(black / area, 0.0, 1.0);
  return static_cast<float>(kBoardWhiteLevel + fraction * (kBoardBlackLevel - kBoardWhiteLevel));
}

}  // namespace

void RenderOptions::Check() const {
  OMNIRIG_CHECK_IN(supersampling, '[', 1, 16, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(noise_sigma);
  OMNIRIG_CHECK_NON_NEGATIVE(blur_sigma_px);
  OMNIRIG_CHECK_IN(vignetting, '[', 0, 1, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(num_threads);
  lighting.Check();
}

void Lighting::Check() const {
  OMNIRIG_CHECK_POSITIVE(gain);
  OMNIRIG_CHECK(tint_rgb.allFinite() && tint_rgb.minCoeff() > 0.0,
                "lighting tint components must be positive");
  OMNIRIG_CHECK(sun_in_world.allFinite() && sun_in_world.norm() > 0.0,
                "the sun direction must be a non-zero vector");
  OMNIRIG_CHECK_IN(sun_share, '[', 0, 1, ']');
}

// Per-camera precomputation: the undistorted normalised-plane point m of every pixel corner
// (lattice point (i, j) is the pixel corner at (i - 0.5, j - 0.5)), and a class per pixel.
struct Renderer::Grid {
  SynthCamera camera;
  int lattice_cols = 0, lattice_rows = 0;
  // At each needed pixel corner: its point on the normalised plane (eq. 3, 4 inverted) and its
  // bearing (eq. 6), nullopt where lifting fails.
  std::vector<Eigen::Vector2d> m;
  std::vector<uint8_t> m_valid;
  std::vector<std::optional<Eigen::Vector3d>> bearing;
  std::vector<uint8_t> lattice_needed;
  std::vector<uint8_t> pixel_class;
  // Per tile of kTilePixels x kTilePixels pixels (row-major), the cone of its corners' bearings.
  int tiles_x = 0, tiles_y = 0;
  std::vector<Cone> tile_cones;

  // The steps of the constructor, in order. A class per pixel (dark, border or inside the
  // mirror's annulus), and the pixel corners that pixels not dark need.
  void ClassifyPixels();
  // m and bearing at every needed pixel corner.
  void LiftLattice(int num_threads);
  void SetTileCones();
};

namespace {

// The cone of the bearings of the lattice points [i0, i1] x [j0, j1] (lattice_cols wide), widened
// by the largest angle between neighbouring lattice points so that it also holds the bearings of
// samples inside the pixels between them.
Cone BearingCone(const std::vector<std::optional<Eigen::Vector3d>>& bearings, int lattice_cols,
                 int i0, int i1, int j0, int j1) {
  auto at = [&](int i, int j) -> const std::optional<Eigen::Vector3d>& {
    return bearings[static_cast<size_t>(j) * lattice_cols + i];
  };
  auto angle = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::acos(std::clamp(a.dot(b) / (a.norm() * b.norm()), -1.0, 1.0));
  };
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double margin = 0.0;
  int count = 0;
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      if (!at(i, j)) continue;
      sum += at(i, j)->normalized();
      ++count;
      if (i < i1 && at(i + 1, j)) margin = std::max(margin, angle(*at(i, j), *at(i + 1, j)));
      if (j < j1 && at(i, j + 1)) margin = std::max(margin, angle(*at(i, j), *at(i, j + 1)));
    }
  }
  Cone cone;
  if (count == 0 || sum.norm() < 1e-6 * count) return cone;  // everything
  cone.axis = sum.normalized();
  double widest = 0.0;
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      if (at(i, j)) widest = std::max(widest, angle(cone.axis, *at(i, j)));
    }
  }
  cone.half_angle_rad = std::min(M_PI, widest + 2.0 * margin);
  return cone;
}

}  // namespace

void Renderer::Grid::ClassifyPixels() {
  const int width = camera.model.width, height = camera.model.height;
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  lattice_cols = width + 1;
  lattice_rows = height + 1;
  pixel_class.assign(static_cast<size_t>(width) * height, kDark);
  lattice_needed.assign(static_cast<size_t>(lattice_cols) * lattice_rows, 0);
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const double r = std::hypot(i - k.u0(), j - k.v0());
      uint8_t cls = kBorder;
      if (r - kHalfPixelDiagonal > camera.rim_radius_px ||
          r + kHalfPixelDiagonal < camera.hole_radius_px) {
        cls = kDark;
      } else if (r + kHalfPixelDiagonal < camera.rim_radius_px &&
                 r - kHalfPixelDiagonal > camera.hole_radius_px) {
        cls = kInside;
      }
      pixel_class[static_cast<size_t>(j) * width + i] = cls;
      if (cls == kDark) continue;
      for (int dj = 0; dj < 2; ++dj) {
        for (int di = 0; di < 2; ++di) {
          lattice_needed[static_cast<size_t>(j + dj) * lattice_cols + i + di] = 1;
        }
      }
    }
  }
}

void Renderer::Grid::LiftLattice(int num_threads) {
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  m.assign(lattice_needed.size(), Eigen::Vector2d::Zero());
  m_valid.assign(lattice_needed.size(), 0);
  bearing.assign(lattice_needed.size(), std::nullopt);
  ParallelRows(lattice_rows, ResolveThreads(num_threads, lattice_rows), [this, &k](int j) {
    for (int i = 0; i < lattice_cols; ++i) {
      const size_t index = static_cast<size_t>(j) * lattice_cols + i;
      if (!lattice_needed[index]) continue;
      // Invert K (eq. 4), then the distortion (eq. 3).
      const double yd = (j - 0.5 - k.v0()) / k.gamma_v();
      const double xd = (i - 0.5 - k.u0()) / k.gamma_u() - k.alpha() * yd;
      const auto undistorted = Undistort(k, Eigen::Vector2d(xd, yd));
      if (!undistorted) continue;
      m[index] = *undistorted;
      m_valid[index] = 1;
      bearing[index] = Lift(NormalisedPlane(k.xi()), *undistorted);
    }
  });
}

void Renderer::Grid::SetTileCones() {
  const int width = camera.model.width, height = camera.model.height;
  tiles_x = (width + kTilePixels - 1) / kTilePixels;
  tiles_y = (height + kTilePixels - 1) / kTilePixels;
  tile_cones.resize(static_cast<size_t>(tiles_x) * tiles_y);
  for (int ty = 0; ty < tiles_y; ++ty) {
    for (int tx = 0; tx < tiles_x; ++tx) {
      tile_cones[static_cast<size_t>(ty) * tiles_x + tx] = BearingCone(
          bearing, lattice_cols, tx * kTilePixels, std::min((tx + 1) * kTilePixels, width),
          ty * kTilePixels, std::min((ty + 1) * kTilePixels, height));
    }
  }
}

Renderer::Renderer(const SynthCamera& camera, int num_threads) {
  camera.Check();
  auto grid = std::make_unique<Grid>();
  grid->camera = camera;
  grid->ClassifyPixels();
  grid->LiftLattice(num_threads);
  grid->SetTileCones();
  grid_ = std::move(grid);
}

Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

const SynthCamera& Renderer::camera() const { return grid_->camera; }

namespace {

// A sample of the s x s rook pattern: its offset (fx, fy) in [0, 1) within the pixel cell,
// measured from the cell's top-left corner (i - 0.5, j - 0.5), and its bilinear weights on the
// cell's corners 00, 10, 01, 11.
struct SubSample {
  double fx, fy;
  double w00, w10, w01, w11;
};

std::vector<SubSample> RookPattern(int s) {
  std::vector<SubSample> samples;
  const double n = static_cast<double>(s) * s;
  for (int a = 0; a < s; ++a) {
    for (int b = 0; b < s; ++b) {
      const double fx = (a * s + b + 0.5) / n, fy = (b * s + a + 0.5) / n;
      samples.push_back({fx, fy, (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy});
    }
  }
  return samples;
}

// The analytic grey level of a pixel whose four corners (normalised-plane points m, in order
// around the pixel) all see the printed side of `board`.
std::optional<float> BoardPixel(
    const FramePrimitive& board, int index,
    const std::array<const std::optional<Eigen::Vector3d>*, 4>& corner_bearings) {
  Polygon quad;
  for (const std::optional<Eigen::Vector3d>* bearing : corner_bearings) {
    Hit hit;
    if (!*bearing || !IntersectOne(board, **bearing, index, &hit) || hit.face != 0) {
      return std::nullopt;
    }
    quad.v[quad.n++] = Eigen::Vector2d(hit.u, hit.v);
  }
  return BoardPixelLevel(board, quad);
}

float Vignetting(double strength, int i, int j, const SynthCamera& camera) {
  if (strength <= 0.0) return 1.0f;
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  const double r2 = ((i - k.u0()) * (i - k.u0()) + (j - k.v0()) * (j - k.v0())) /
                    (camera.rim_radius_px * camera.rim_radius_px);
  return static_cast<float>(1.0 - strength * r2);
}

struct FrameContext {
  const SynthCamera* camera = nullptr;
  UnifiedIntrinsics plane;         // NormalisedPlane(xi)
  double rim2 = 0.0, hole2 = 0.0;  // squared mirror radii, pixels^2
  std::vector<FramePrimitive> prims;
  Eigen::Vector3f background;
  std::vector<SubSample> samples;
  std::vector<int> lattice_hit;  // primitive hit at each pixel corner, -1 for none
  // Per tile of kTilePixels x kTilePixels pixels: the primitives its rays may hit.
  int tiles_x = 0;
  std::vector<std::vector<int>> tile_candidates;

  // The candidates of the tile holding pixel (i, j), or lattice point (i, j) (the last lattice
  // column and row belong to the last tiles).
  const std::vector<int>& TileCandidates(int i, int j) const {
    const int tiles_y = static_cast<int>(tile_candidates.size()) / tiles_x;
    return tile_candidates[static_cast<size_t>(std::min(j / kTilePixels, tiles_y - 1)) * tiles_x +
                           std::min(i / kTilePixels, tiles_x - 1)];
  }
};

// A pixel's four corners (order 00, 10, 01, 11) on the normalised plane and their bearings, and
// the primitive that all four hit (-1 for none) when `uniform`.
struct PixelCorners {
  std::array<const Eigen::Vector2d*, 4> m;
  std::array<const std::optional<Eigen::Vector3d>*, 4> bearing;
  bool uniform = false;
  int primitive = -1;
};

// Whether sample `f` of pixel (i, j) falls outside the mirror annulus.
inline bool SampleIsDark(const FrameContext& frame, int i, int j, const SubSample& f) {
  const UnifiedIntrinsics& k = frame.camera->model.intrinsics;
  const double dx = i - 0.5 + f.fx - k.u0(), dy = j - 0.5 + f.fy - k.v0();
  const double r2 = dx * dx + dy * dy;
  return r2 > frame.rim2 || r2 < frame.hole2;
}

// Every sample is lifted and cast; samples of a uniform pixel test its primitive first.
Eigen::Vector3f ShadeSampled(const FrameContext& frame, int i, int j, bool border,
                             const PixelCorners& corners) {
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  const Eigen::Vector2d &m00 = *corners.m[0], &m10 = *corners.m[1], &m01 = *corners.m[2],
                        &m11 = *corners.m[3];
  const int id = corners.primitive;
  for (const SubSample& f : frame.samples) {
    if (border && SampleIsDark(frame, i, j, f)) {
      sum += Eigen::Vector3f::Constant(static_cast<float>(kDarkLevel));
      continue;
    }
    const double mx = f.w00 * m00.x() + f.w10 * m10.x() + f.w01 * m01.x() + f.w11 * m11.x();
    const double my = f.w00 * m00.y() + f.w10 * m10.y() + f.w01 * m01.y() + f.w11 * m11.y();
    const auto bearing = Lift(frame.plane, Eigen::Vector2d(mx, my));
    Hit hit;  // a sample outside lifting's domain sees nothing
    if (bearing &&
        (!corners.uniform || (id >= 0 && !IntersectOne(frame.prims[id], *bearing, id, &hit)))) {
      hit = IntersectAll(frame.prims, frame.TileCandidates(i, j), *bearing);
    }
    sum += Shade(frame.prims, hit, frame.background);
  }
  return sum / static_cast<float>(frame.samples.size());
}

// A pixel whose four corners see the same face of one textured primitive: the samples' surface
// coordinates are interpolated bilinearly from the corners' (the map is affine over a pixel to
// within 1e-3 px, as for the board), which spares a ray cast per sample. nullopt when the
// corners do not share a face (or straddle a cylinder's texture seam).
std::optional<Eigen::Vector3f> ShadeSurfaceByInterpolation(const FrameContext& frame, int i, int j,
                                                           bool border,
                                                           const PixelCorners& corners) {
  const int id = corners.primitive;
  const FramePrimitive& prim = frame.prims[id];
  std::array<Hit, 4> hits;
  for (int q = 0; q < 4; ++q) {
    const std::optional<Eigen::Vector3d>& bearing = *corners.bearing[q];
    if (!bearing || !IntersectOne(prim, *bearing, id, &hits[q]) || hits[q].face != hits[0].face) {
      return std::nullopt;
    }
  }
  if (prim.kind == PrimitiveInfo::Kind::kCylinder && hits[0].face == 0) {
    const auto [lo, hi] = std::minmax({hits[0].u, hits[1].u, hits[2].u, hits[3].u});
    if (hi - lo > M_PI * prim.half_size.x()) return std::nullopt;
  }
  const FaceTexture& face = prim.faces[hits[0].face];
  if (face.image == nullptr) return std::nullopt;
  float texture_sum = 0.0f;
  int dark = 0;
  for (const SubSample& f : frame.samples) {
    if (border && SampleIsDark(frame, i, j, f)) {
      ++dark;
      continue;
    }
    const double u = f.w00 * hits[0].u + f.w10 * hits[1].u + f.w01 * hits[2].u + f.w11 * hits[3].u;
    const double v = f.w00 * hits[0].v + f.w10 * hits[1].v + f.w01 * hits[2].v + f.w11 * hits[3].v;
    texture_sum += SampleTexture(face, u, v);
  }
  const Eigen::Vector3f sum =
      face.rgb * texture_sum + Eigen::Vector3f::Constant(static_cast<float>(dark * kDarkLevel));
  return sum / static_cast<float>(frame.samples.size());
}

// The colour (RGB, 0-255) of pixel (i, j) of class `cls` (not dark).
Eigen::Vector3f ShadePixel(const FrameContext& frame, int i, int j, uint8_t cls,
                           const PixelCorners& corners) {
  const bool border = cls == kBorder;
  if (corners.uniform && corners.primitive < 0 && !border) return frame.background;
  if (corners.uniform && corners.primitive >= 0) {
    const FramePrimitive& prim = frame.prims[corners.primitive];
    if (prim.kind == PrimitiveInfo::Kind::kCheckerboard) {
      if (!border) {
        const auto level = BoardPixel(
            prim, corners.primitive,
            {corners.bearing[0], corners.bearing[1], corners.bearing[3], corners.bearing[2]});
        if (level) return Eigen::Vector3f::Constant(*level);
      }
    } else if (frame.samples.size() > 4) {
      // With few samples, casting each is cheaper than casting the four corners.
      if (const auto colour = ShadeSurfaceByInterpolation(frame, i, j, border, corners)) {
        return *colour;
      }
    }
  }
  return ShadeSampled(frame, i, j, border, corners);
}

FrameContext MakeFrameContext(const Scene& scene, const SynthCamera& camera,
                              const Rigid3d& cam_from_world, const RenderOptions& options,
                              const std::vector<Cone>& tile_cones, int tiles_x) {
  FrameContext frame;
  frame.camera = &camera;
  frame.plane = NormalisedPlane(camera.model.intrinsics.xi());
  frame.rim2 = camera.rim_radius_px * camera.rim_radius_px;
  frame.hole2 = camera.hole_radius_px * camera.hole_radius_px;
  for (int i = 0; i < static_cast<int>(scene.primitives().size()); ++i) {
    frame.prims.push_back(MakeFramePrimitive(scene, i, cam_from_world, options.lighting));
  }
  frame.tiles_x = tiles_x;
  frame.tile_candidates.resize(tile_cones.size());
  for (size_t tile = 0; tile < tile_cones.size(); ++tile) {
    for (int i = 0; i < static_cast<int>(frame.prims.size()); ++i) {
      if (ConeMayHit(frame.prims[i], tile_cones[tile])) frame.tile_candidates[tile].push_back(i);
    }
  }
  const Lighting& lighting = options.lighting;
  frame.background = (scene.background_rgb() * 255.0)
                         .cwiseProduct(lighting.gain * lighting.tint_rgb)
                         .cast<float>();
  frame.samples = RookPattern(options.supersampling);
  return frame;
}

// The sensor: blur, grey conversion and noise on the radiance (BGR, 0-255), then 8 bits.
cv::Mat SensorImage(cv::Mat radiance, const RenderOptions& options) {
  if (options.blur_sigma_px > 0.0) {
    cv::GaussianBlur(radiance, radiance, cv::Size(0, 0), options.blur_sigma_px, 0.0,
                     cv::BORDER_REPLICATE);
  }
  if (options.grayscale) cv::cvtColor(radiance, radiance, cv::COLOR_BGR2GRAY);
  if (options.noise_sigma > 0.0) {
    cv::Mat noise(radiance.size(), radiance.type());
    cv::RNG rng(options.seed ^ 0x5DEECE66Dull);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
    radiance += noise;
  }
  cv::Mat image;
  radiance.convertTo(image, options.grayscale ? CV_8UC1 : CV_8UC3);
  return image;
}

}  // namespace

cv::Mat Renderer::Render(const Scene& scene, const Rigid3d& cam_from_world,
                         const RenderOptions& options) const {
  options.Check();
  return SensorImage(Radiance(scene, cam_from_world, options), options);
}

cv::Mat Renderer::Render(const Scene& scene,
                         const std::vector<Rigid3d>& cam_from_world_during_exposure,
                         const RenderOptions& options) const {
  options.Check();
  OMNIRIG_CHECK(!cam_from_world_during_exposure.empty(), "an exposure needs at least one pose");
  cv::Mat sum = Radiance(scene, cam_from_world_during_exposure.front(), options);
  for (size_t k = 1; k < cam_from_world_during_exposure.size(); ++k) {
    sum += Radiance(scene, cam_from_world_during_exposure[k], options);
  }
  if (cam_from_world_during_exposure.size() > 1) {
    sum /= static_cast<double>(cam_from_world_during_exposure.size());
  }
  return SensorImage(std::move(sum), options);
}

cv::Mat Renderer::Radiance(const Scene& scene, const Rigid3d& cam_from_world,
                           const RenderOptions& options) const {
  const Grid& g = *grid_;
  const SynthCamera& camera = g.camera;
  const int width = camera.model.width, height = camera.model.height;
  const int threads = ResolveThreads(options.num_threads, height);

  FrameContext frame =
      MakeFrameContext(scene, camera, cam_from_world, options, g.tile_cones, g.tiles_x);

  // Pass 1: the primitive hit at every needed pixel corner.
  frame.lattice_hit.assign(g.m.size(), -1);
  ParallelRows(g.lattice_rows, threads, [&](int j) {
    for (int i = 0; i < g.lattice_cols; ++i) {
      const size_t index = static_cast<size_t>(j) * g.lattice_cols + i;
      const std::optional<Eigen::Vector3d>& bearing = g.bearing[index];
      if (bearing) {
        frame.lattice_hit[index] =
            IntersectAll(frame.prims, frame.TileCandidates(i, j), *bearing).primitive;
      }
    }
  });

  // Pass 2: pixels.
  cv::Mat radiance(height, width, CV_32FC3);
  const float dark = static_cast<float>(kDarkLevel);
  ParallelRows(height, threads, [&](int j) {
    cv::Vec3f* out = radiance.ptr<cv::Vec3f>(j);
    for (int i = 0; i < width; ++i) {
      const uint8_t cls = g.pixel_class[static_cast<size_t>(j) * width + i];
      const size_t c00 = static_cast<size_t>(j) * g.lattice_cols + i, c10 = c00 + 1;
      const size_t c01 = c00 + g.lattice_cols, c11 = c01 + 1;
      if (cls == kDark || !(g.m_valid[c00] && g.m_valid[c10] && g.m_valid[c01] && g.m_valid[c11])) {
        out[i] = cv::Vec3f(dark, dark, dark);
        continue;
      }
      PixelCorners corners;
      corners.m = {&g.m[c00], &g.m[c10], &g.m[c01], &g.m[c11]};
      corners.bearing = {&g.bearing[c00], &g.bearing[c10], &g.bearing[c01], &g.bearing[c11]};
      corners.primitive = frame.lattice_hit[c00];
      corners.uniform = corners.primitive == frame.lattice_hit[c10] &&
                        corners.primitive == frame.lattice_hit[c01] &&
                        corners.primitive == frame.lattice_hit[c11];
      const Eigen::Vector3f rgb =
          ShadePixel(frame, i, j, cls, corners) * Vignetting(options.vignetting, i, j, camera);
      out[i] = cv::Vec3f(rgb.z(), rgb.y(), rgb.x());  // RGB -> BGR
    }
  });

  return radiance;
}

cv::Mat Render(const Scene& scene, const SynthCamera& camera, const Rigid3d& cam_from_world,
               const RenderOptions& options) {
  // A small cache of renderers keyed by the camera, so that repeated calls pay the per-camera
  // precomputation once.
  static std::mutex mutex;
  static std::vector<std::shared_ptr<const Renderer>> cache;
  constexpr size_t kCacheSize = 4;
  std::shared_ptr<const Renderer> renderer;
  {
    std::lock_guard<std::mutex> lock(mutex);
    for (const auto& candidate : cache) {
      const SynthCamera& c = candidate->camera();
      if (c.model.intrinsics.params == camera.model.intrinsics.params &&
          c.model.width == camera.model.width && c.model.height == camera.model.height &&
          c.rim_radius_px == camera.rim_radius_px && c.hole_radius_px == camera.hole_radius_px) {
        renderer = candidate;
        break;
      }
    }
  }
  if (!renderer) {
    renderer = std::make_shared<const Renderer>(camera, options.num_threads);
    std::lock_guard<std::mutex> lock(mutex);
    cache.insert(cache.begin(), renderer);
    if (cache.size() > kCacheSize) cache.pop_back();
  }
  return renderer->Render(scene, cam_from_world, options);
}

}  // namespace omnirig::synth
