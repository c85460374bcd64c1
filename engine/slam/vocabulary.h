#pragma once
// A bag of visual words over SIFT descriptors for place recognition (Nister and Stewenius's
// vocabulary tree, scored as DBoW2 does): hierarchical k-means with `branching` children per
// node and `depth` levels, so a descriptor finds its word in branching * depth distances instead
// of branching^depth. Words are weighted by tf-idf and an image's vector is L1-normalised; two
// images score sum_w min(v_w, u_w) in [0, 1] (DBoW2's L1 score, 1 - |v - u|_1 / 2).
//
// The shipped vocabulary (DefaultVocabulary) is trained once by bench/train_vocabulary.cc on
// renders of scenes and seeds that no test or benchmark uses, and compiled into the library from
// engine/slam/data/vocabulary.bin: nothing is downloaded or read from disk at run time.

#include <cstdint>
#include <functional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

namespace omnirig::slam {

// Sparse tf-idf vector: (word, weight) sorted by word, weights summing to 1.
using BowVector = std::vector<std::pair<int, float>>;

class Vocabulary {
 public:
  static constexpr int kDescriptorSize = 128;  // SIFT

  Vocabulary() = default;
  // A trained tree (testing/slam/vocabulary_training.h trains one): `branching` children per
  // node, `depth` levels; `centres` and `valid` per node in the layout of centres_ below, `idf`
  // per word. Throws InvalidArgument for a shape out of range or arrays that do not fit it.
  Vocabulary(int branching, int depth, std::vector<std::uint8_t> centres, std::vector<char> valid,
             std::vector<float> idf);
  // The binary form (a header, then the centres as bytes: SIFT's components are integers in
  // [0, 255]; then the idf as float32). Throws InvalidArgument on a malformed blob.
  std::vector<std::uint8_t> Serialize() const;
  static Vocabulary Deserialize(const std::uint8_t* data, std::size_t size);

  bool empty() const { return num_words() == 0; }
  int num_words() const { return idf_.empty() ? 0 : static_cast<int>(idf_.size()); }
  // The word of one descriptor (kDescriptorSize floats).
  int Word(const float* descriptor) const;
  // The tf-idf vector of an image's descriptors (CV_32F or CV_8U rows); with `words`, also
  // each row's word.
  BowVector Transform(const cv::Mat& descriptors, std::vector<int>* words = nullptr) const;
  // The node of the tree at `level` (1 = the root's children, depth() = the word itself) that
  // holds `word`, numbered 0 .. branching^level - 1: descriptors under different nodes are
  // unlikely matches, so matching can stay within one node (DBoW2's direct index).
  int NodeOf(int word, int level) const;
  int depth() const { return depth_; }

 private:
  int NumNodes() const;
  int FirstLeaf() const;

  int branching_ = 0;
  int depth_ = 0;
  // Nodes of the complete tree in breadth-first order without the root: node n's children are
  // n * branching + 1 .. n * branching + branching (the root is node 0). Empty nodes (a cluster
  // with fewer descriptors than children) are marked in valid_.
  std::vector<std::uint8_t> centres_;  // (NumNodes()) x kDescriptorSize, node 0's unused
  std::vector<char> valid_;
  std::vector<float> idf_;  // per word (leaf)
};

// Place recognition's index over keyframes: an inverted file from word to the keyframes holding
// it, so a query visits only keyframes that share words with it.
class KeyframeDatabase {
 public:
  struct Candidate {
    int keyframe = -1;
    double score = 0.0;  // DBoW2's L1 score (see the top)
  };
  void Add(int keyframe, const BowVector& bow);
  // The keyframes `accept` lets through, scoring at least min_score, best first, at most
  // max_results.
  std::vector<Candidate> Query(const BowVector& bow, const std::function<bool(int)>& accept,
                               double min_score, int max_results) const;

 private:
  std::unordered_map<int, std::vector<std::pair<int, float>>> keyframes_of_word_;
};

// The vocabulary compiled into the library (engine/slam/data/vocabulary.bin), parsed once on
// first use (~1 ms).
const Vocabulary& DefaultVocabulary();

}  // namespace omnirig::slam
