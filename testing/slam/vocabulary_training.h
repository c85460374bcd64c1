#pragma once
// Training of SLAM's bag-of-words vocabulary (engine/slam/vocabulary.h), for
// bench/train_vocabulary (which trains the shipped engine/slam/data/vocabulary.bin) and the
// vocabulary's tests; and the L1 score of two word vectors, the reference for
// KeyframeDatabase's scores.

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/slam/vocabulary.h"

namespace omnirig::slam {

// Hierarchical k-means (cv::kmeans, k-means++ seeding, `seed`) over every descriptor of
// `images` (CV_32F, Vocabulary::kDescriptorSize columns, one matrix per image) into a tree of
// `branching` children per node and `depth` levels; the idf of a word is log(N / n_w) with N
// images, n_w of them holding the word.
Vocabulary TrainVocabulary(const std::vector<cv::Mat>& images, int branching, int depth,
                           std::uint64_t seed);

// DBoW2's L1 score of two L1-normalised vectors: 1 for identical word histograms, 0 for disjoint.
double BowScore(const BowVector& a, const BowVector& b);

}  // namespace omnirig::slam
