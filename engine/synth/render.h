#pragma once
// The synthetic omnidirectional renderer: a ray caster through Mei's unified model.
//
// Every pixel is the mean of s x s samples (RenderOptions::supersampling = s) at a "rook"
// pattern: sample (a, b) sits at offset ((a s + b + 0.5) / s^2 - 0.5, (b s + a + 0.5) / s^2 - 0.5)
// from the pixel centre, so that all s^2 samples have distinct columns and rows (s^2 + 1 coverage
// levels for near-horizontal and near-vertical edges) and the pattern is point-symmetric about
// the pixel centre (edges and corners are not shifted). Each sample is lifted (inverse of the
// distortion, then eq. 6 of the paper) to a bearing, cast into the scene (nearest hit) and shaded.
// Samples outside the mirror rim or inside the hole are dark.
//
// Checkerboards are box-filtered exactly instead: a pixel whose four corners all see the board's
// printed side gets the black-area fraction of its footprint on the board (the quadrilateral of
// its corners' board points; the map is affine over a pixel to within 1e-3 px). Corners and
// edges therefore carry no sampling error at any supersampling; only pixels on the board's
// outline are sampled.
//
// Speed: the undistorted normalised-plane points m of the pixel corners are computed once per
// camera (the Newton inversion of the distortion is the expensive part of lifting) and
// interpolated bilinearly to the samples; the distortion is a smooth polynomial, so the
// interpolation error is below 1e-4 px (measured), and eq. (6) is then applied exactly per
// sample. The hit primitive is found at the pixel corners. Samples of a pixel whose four corners
// hit the same primitive test only that primitive, so an object thinner than a pixel that
// touches no corner of that pixel can be missed there (harmless for boards, walls, furniture).
// With more than 4 samples per pixel, a pixel whose four corners see the same face of a textured
// primitive takes its samples' texture coordinates by bilinear interpolation of the corners'
// (affine over a pixel to within 1e-3 px, as for the board) instead of casting every sample;
// other pixels (silhouettes, face edges, the board's outline) cast every sample.
//
// Which primitives a ray may hit is decided per tile of 16 x 16 pixels: a tile's bearings lie in
// a cone (precomputed per camera), and only primitives whose bounding sphere meets the cone are
// tested, in scene order, so the nearest hit is the same as when testing all of them. A scene of
// a few hundred primitives (a city block) thus costs about what a room costs.
//
// Pixel convention: the centre of the top-left pixel is (0, 0), as in unified_camera.h and
// cv::cornerSubPix.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/rigid3.h"
#include "engine/synth/scene.h"
#include "engine/synth/synth_camera.h"

namespace omnirig::synth {

// A global illumination term, cheap to evaluate: the colour of every textured face (and of the
// sky) is scaled by
//   gain * tint_rgb * ((1 - sun_share) + 2 sun_share max(0, n . sun_in_world))
// where n is the face's unit normal on the side the camera sees (a cylinder's side takes the
// mean over its circumference, 2 |sun_xy| / pi for the directional part; the sky takes no
// directional part). Checkerboards are printed matter lit by the calibration set-up: unchanged.
// The default changes nothing (the factor is exactly 1).
struct Lighting {
  double gain = 1.0;                                       // > 0
  Eigen::Vector3d tint_rgb{1.0, 1.0, 1.0};                 // components > 0
  Eigen::Vector3d sun_in_world{0.0, 0.0, 1.0};             // towards the light, non-zero
  double sun_share = 0.0;                                  // in [0, 1]

  void Check() const;
};

struct RenderOptions {
  int supersampling = 4;       // s: s x s samples per pixel (1 .. 16)
  double noise_sigma = 0.0;    // additive Gaussian noise, grey levels (0 .. 255 scale)
  double blur_sigma_px = 0.0;  // Gaussian blur (optics), applied before the noise
  double vignetting = 0.0;     // brightness scaled by 1 - vignetting * (r / rim)^2, in [0, 1]
  uint64_t seed = 0;           // of the noise; the same seed gives the same image
  int num_threads = 0;         // 0 = all cores
  bool grayscale = false;      // CV_8UC1 instead of CV_8UC3 (BGR)
  Lighting lighting;

  void Check() const;  // throws InvalidArgument on out-of-range values
};

// Grey level of dark pixels (outside the rim, inside the hole) before noise.
inline constexpr double kDarkLevel = 6.0;
// Grey levels of the board's black and white squares (and the white margin).
inline constexpr double kBoardBlackLevel = 25.0;
inline constexpr double kBoardWhiteLevel = 235.0;

// Renders with a camera whose per-pixel lifting is precomputed once (0.1-0.2 s for 1024x768);
// reuse one Renderer for every frame of a camera. Thread-safe: Render() is const.
class Renderer {
 public:
  explicit Renderer(const SynthCamera& camera, int num_threads = 0);
  ~Renderer();
  Renderer(Renderer&&) noexcept;
  Renderer& operator=(Renderer&&) noexcept;

  // An 8-bit BGR (or grey) image of `scene` seen from cam_from_world.
  cv::Mat Render(const Scene& scene, const Rigid3d& cam_from_world,
                 const RenderOptions& options) const;

  // Motion blur: the mean radiance over the camera poses of one exposure (at least one), then
  // the sensor (blur, noise, 8 bits) once. One pose gives exactly Render()'s image.
  cv::Mat Render(const Scene& scene, const std::vector<Rigid3d>& cam_from_world_during_exposure,
                 const RenderOptions& options) const;

  const SynthCamera& camera() const;

 private:
  struct Grid;
  // The radiance (CV_32FC3, BGR, 0-255) before the sensor.
  cv::Mat Radiance(const Scene& scene, const Rigid3d& cam_from_world,
                   const RenderOptions& options) const;
  std::unique_ptr<const Grid> grid_;
};

// Convenience: renders through a Renderer cached for the last few cameras (process-wide,
// thread-safe), so that repeated calls with one camera pay the precomputation once.
cv::Mat Render(const Scene& scene, const SynthCamera& camera, const Rigid3d& cam_from_world,
               const RenderOptions& options);

}  // namespace omnirig::synth
