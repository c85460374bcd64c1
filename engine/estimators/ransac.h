#pragma once
// A generic, seeded RANSAC (Fischler & Bolles 1981) with local optimisation (Chum et al. 2003),
// separate from any minimal solver so that every robust estimator in omnirig shares one loop.
//
// An Estimator provides:
//   using Model = ...;
//   static constexpr int kMinSampleSize;
//   // Fits models to the data at `sample` (indices); may produce zero or several models.
//   void Estimate(const std::vector<int>& sample, std::vector<Model>* models) const;
//   // Fits one model to many data (the local optimisation on a consensus set); returns false
//   // when the fit is degenerate.
//   bool Refit(const std::vector<int>& indices, Model* model) const;
//   // Residual of datum i under `model`, in the unit of RansacOptions::max_error.
//   double Error(const Model& model, int i) const;
//   int NumData() const;
//
// Determinism: samples come from a std::mt19937_64 seeded with RansacOptions::seed and mapped
// to indices by our own rejection sampling (not std::uniform_int_distribution, whose output is
// implementation-defined), so one input and one seed give one output on every platform.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "engine/util/option_check.h"

namespace omnirig {

struct RansacOptions {
  // Inlier threshold on Estimator::Error, in its unit.
  double max_error = 0.0;
  int min_iterations = 0;
  int max_iterations = 10000;
  // Probability that at least one sample is all inliers when the loop stops early.
  double confidence = 0.999;
  uint64_t seed = 0;
  // Run Refit on the consensus set whenever the best model improves.
  bool local_optimization = true;

  void Check() const {
    OMNIRIG_CHECK_POSITIVE(max_error);
    OMNIRIG_CHECK(
        min_iterations >= 0 && max_iterations >= 1 && min_iterations <= max_iterations,
        "RansacOptions: need 0 <= min_iterations <= max_iterations and max_iterations >= 1");
    OMNIRIG_CHECK_IN(confidence, '(', 0, 1, ')');
  }
};

template <typename Model>
struct RansacReport {
  bool success = false;
  Model model{};
  std::vector<char> inlier_mask;  // one entry per datum, 1 for inliers of `model`
  int num_inliers = 0;
  int num_iterations = 0;
};

namespace internal {

// Uniform integer in [0, n) by rejection, independent of the standard library's distributions.
inline int UniformIndex(std::mt19937_64& rng, int n) {
  const uint64_t range = static_cast<uint64_t>(n);
  const uint64_t limit =
      std::numeric_limits<uint64_t>::max() - std::numeric_limits<uint64_t>::max() % range;
  uint64_t x;
  do {
    x = rng();
  } while (x >= limit);
  return static_cast<int>(x % range);
}

// k distinct indices in [0, n) (k is small: a partial Fisher-Yates would need O(n) memory).
inline void SampleDistinct(std::mt19937_64& rng, int n, int k, std::vector<int>* sample) {
  sample->clear();
  while (static_cast<int>(sample->size()) < k) {
    const int i = UniformIndex(rng, n);
    if (std::find(sample->begin(), sample->end(), i) == sample->end()) sample->push_back(i);
  }
}

// Iterations needed to draw one all-inlier sample with probability `confidence`.
inline int RequiredIterations(double inlier_ratio, int sample_size, double confidence,
                              int max_iterations) {
  const double p_good = std::pow(inlier_ratio, sample_size);
  if (p_good <= 0.0) return max_iterations;
  if (p_good >= 1.0) return 1;
  const double n = std::log(1.0 - confidence) / std::log(1.0 - p_good);
  if (!std::isfinite(n) || n > max_iterations) return max_iterations;
  return std::max(1, static_cast<int>(std::ceil(n)));
}

template <typename Estimator>
int CountInliers(const Estimator& estimator, const typename Estimator::Model& model,
                 double max_error, std::vector<char>* mask) {
  const int n = estimator.NumData();
  mask->assign(n, 0);
  int count = 0;
  for (int i = 0; i < n; ++i) {
    if (estimator.Error(model, i) <= max_error) {
      (*mask)[i] = 1;
      ++count;
    }
  }
  return count;
}

}  // namespace internal

// Runs RANSAC. Never throws for degenerate data: an unsuccessful report comes back instead.
// Throws InvalidArgument for invalid options.
template <typename Estimator>
RansacReport<typename Estimator::Model> Ransac(const Estimator& estimator,
                                               const RansacOptions& options) {
  options.Check();
  using Model = typename Estimator::Model;
  RansacReport<Model> report;
  const int n = estimator.NumData();
  const int k = Estimator::kMinSampleSize;
  if (n < k) return report;

  std::mt19937_64 rng(options.seed);
  std::vector<int> sample;
  std::vector<Model> models;
  std::vector<char> mask;
  std::vector<int> inliers;
  int required = options.max_iterations;
  int it = 0;
  for (; it < std::max(required, options.min_iterations) && it < options.max_iterations; ++it) {
    internal::SampleDistinct(rng, n, k, &sample);
    models.clear();
    estimator.Estimate(sample, &models);
    for (Model& model : models) {
      int count = internal::CountInliers(estimator, model, options.max_error, &mask);
      if (count <= report.num_inliers) continue;
      if (options.local_optimization && count > k) {
        // Refit on the consensus set and keep the refit only when it explains more data.
        Model refit = model;
        inliers.clear();
        for (int i = 0; i < n; ++i) {
          if (mask[i]) inliers.push_back(i);
        }
        std::vector<char> refit_mask;
        if (estimator.Refit(inliers, &refit)) {
          const int refit_count =
              internal::CountInliers(estimator, refit, options.max_error, &refit_mask);
          if (refit_count >= count) {
            model = refit;
            count = refit_count;
            mask.swap(refit_mask);
          }
        }
      }
      report.success = true;
      report.model = model;
      report.num_inliers = count;
      report.inlier_mask = mask;
      required = internal::RequiredIterations(static_cast<double>(count) / n, k, options.confidence,
                                              options.max_iterations);
    }
  }
  report.num_iterations = it;
  return report;
}

}  // namespace omnirig
