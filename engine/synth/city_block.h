#pragma once
// The city block of the loop sequences (StereoSequenceOptions::Environment::kCityBlock): a block
// of buildings, a street around it lined with buildings on its far side, poles and parked cars,
// and the closed path the rig drives along the street.
//
// World frame: z up, ground at z = 0, the block centred on the origin with its long side along x.
// The block's core is a rectangle of 2 x 1 aspect; the path's centreline is the rounded
// rectangle at kPathOffsetM from the core (so its corners are quarter circles of that radius),
// driven counter-clockwise seen from above, starting in the middle of the south side heading +x.

#include <cstdint>

#include <Eigen/Core>

#include "engine/synth/scene.h"

namespace omnirig::synth {

class CityBlockLoop {
 public:
  static constexpr double kPathOffsetM = 4.0;  // centreline to the block's façades
  static constexpr double kFarFacadeM = 5.0;   // centreline to the façades across the street
  static constexpr double kMinLengthM = 40.0;
  static constexpr double kMaxLengthM = 400.0;

  // A loop of centreline length length_m in [kMinLengthM, kMaxLengthM] (throws InvalidArgument
  // otherwise).
  explicit CityBlockLoop(double length_m);

  double length_m() const { return length_m_; }
  // Half extents of the block's core rectangle (x, y), metres.
  Eigen::Vector2d core_half_size() const { return core_half_; }

  // The centreline at arclength u (metres from the start, any real: the loop repeats), and the
  // unit normal there pointing away from the block.
  void At(double u, Eigen::Vector2d* point, Eigen::Vector2d* outward) const;

 private:
  double length_m_;
  Eigen::Vector2d core_half_;
};

// The scene around `loop`: deterministic in seed.
Scene MakeCityBlockScene(const CityBlockLoop& loop, uint64_t seed);

}  // namespace omnirig::synth
