#include "engine/slam/vocabulary.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <map>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

constexpr std::uint32_t kMagic = 0x57424f4f;  // "OOBW"
constexpr int kHeaderInts = 4;                // magic, branching, depth, descriptor size

float SquaredDistance(const float* a, const std::uint8_t* b) {
  float sum = 0;
  for (int i = 0; i < Vocabulary::kDescriptorSize; ++i) {
    const float d = a[i] - static_cast<float>(b[i]);
    sum += d * d;
  }
  return sum;
}

int Power(int base, int exponent) {
  int value = 1;
  for (int i = 0; i < exponent; ++i) value *= base;
  return value;
}

void CheckShape(int branching, int depth) {
  OMNIRIG_CHECK(branching >= 2 && depth >= 1 && Power(branching, depth) <= (1 << 20),
                "vocabulary: invalid tree shape");
}

}  // namespace

Vocabulary::Vocabulary(int branching, int depth, std::vector<std::uint8_t> centres,
                       std::vector<char> valid, std::vector<float> idf)
    : branching_(branching),
      depth_(depth),
      centres_(std::move(centres)),
      valid_(std::move(valid)),
      idf_(std::move(idf)) {
  CheckShape(branching_, depth_);
  const std::size_t num_nodes = NumNodes();
  OMNIRIG_CHECK(valid_.size() == num_nodes && centres_.size() == num_nodes * kDescriptorSize &&
                    idf_.size() == static_cast<std::size_t>(Power(branching_, depth_)),
                "vocabulary: arrays that do not fit a tree of branching "
                    << branching_ << " and depth " << depth_);
}

int Vocabulary::NumNodes() const {
  return (Power(branching_, depth_ + 1) - 1) / (branching_ - 1);
}

int Vocabulary::FirstLeaf() const { return (Power(branching_, depth_) - 1) / (branching_ - 1); }

int Vocabulary::Word(const float* descriptor) const {
  OMNIRIG_CHECK(!empty(), "the vocabulary is empty");
  int node = 0;
  for (int d = 0; d < depth_; ++d) {
    int best = -1;
    float best_distance = std::numeric_limits<float>::max();
    for (int c = 1; c <= branching_; ++c) {
      const int child = node * branching_ + c;
      if (!valid_[child]) continue;
      const float distance =
          SquaredDistance(descriptor, &centres_[static_cast<std::size_t>(child) * kDescriptorSize]);
      if (distance < best_distance) {
        best_distance = distance;
        best = child;
      }
    }
    if (best < 0) break;  // a leaf above the last level (training had too few descriptors)
    node = best;
  }
  // A node above the last level stands for its first descendant leaf.
  while (node < FirstLeaf()) node = node * branching_ + 1;
  return node - FirstLeaf();
}

BowVector Vocabulary::Transform(const cv::Mat& descriptors, std::vector<int>* words) const {
  BowVector vector;
  if (words) words->clear();
  if (descriptors.empty()) return vector;
  OMNIRIG_CHECK(descriptors.cols == kDescriptorSize, "a bag of words needs SIFT descriptors");
  cv::Mat f;
  descriptors.convertTo(f, CV_32F);
  std::map<int, float> weights;
  for (int r = 0; r < f.rows; ++r) {
    const int word = Word(f.ptr<float>(r));
    weights[word] += idf_[word];
    if (words) words->push_back(word);
  }
  double sum = 0;
  for (const auto& [word, weight] : weights) sum += weight;
  if (sum <= 0) return vector;
  vector.reserve(weights.size());
  for (const auto& [word, weight] : weights) {
    if (weight > 0) vector.emplace_back(word, static_cast<float>(weight / sum));
  }
  return vector;
}

int Vocabulary::NodeOf(int word, int level) const {
  OMNIRIG_CHECK(level >= 1 && level <= depth_, "vocabulary level out of range");
  // Leaves are numbered in breadth-first order of a complete tree: the word's digits in base
  // `branching` are its path from the root.
  return word / Power(branching_, depth_ - level);
}

std::vector<std::uint8_t> Vocabulary::Serialize() const {
  const std::uint32_t header[kHeaderInts] = {kMagic, static_cast<std::uint32_t>(branching_),
                                             static_cast<std::uint32_t>(depth_),
                                             static_cast<std::uint32_t>(kDescriptorSize)};
  std::vector<std::uint8_t> bytes(sizeof(header));
  std::memcpy(bytes.data(), header, sizeof(header));
  for (int node = 0; node < NumNodes(); ++node) bytes.push_back(valid_[node] ? 1 : 0);
  bytes.insert(bytes.end(), centres_.begin(), centres_.end());
  const std::size_t offset = bytes.size();
  bytes.resize(offset + idf_.size() * sizeof(float));
  std::memcpy(bytes.data() + offset, idf_.data(), idf_.size() * sizeof(float));
  return bytes;
}

Vocabulary Vocabulary::Deserialize(const std::uint8_t* data, std::size_t size) {
  std::uint32_t header[kHeaderInts] = {};
  OMNIRIG_CHECK(size >= sizeof(header), "vocabulary: truncated header");
  std::memcpy(header, data, sizeof(header));
  OMNIRIG_CHECK(header[0] == kMagic && header[3] == kDescriptorSize,
                "vocabulary: not a SIFT vocabulary file");
  const int branching = static_cast<int>(header[1]), depth = static_cast<int>(header[2]);
  CheckShape(branching, depth);
  const std::size_t num_words = Power(branching, depth);
  const std::size_t num_nodes = (num_words * branching - 1) / (branching - 1);
  const std::size_t expected =
      sizeof(header) + num_nodes * (1 + kDescriptorSize) + num_words * sizeof(float);
  OMNIRIG_CHECK(size == expected, "vocabulary: " << size << " bytes, expected " << expected);
  const std::uint8_t* valid = data + sizeof(header);
  const std::uint8_t* centres = valid + num_nodes;
  std::vector<float> idf(num_words);
  std::memcpy(idf.data(), centres + num_nodes * kDescriptorSize, num_words * sizeof(float));
  return Vocabulary(branching, depth,
                    std::vector<std::uint8_t>(centres, centres + num_nodes * kDescriptorSize),
                    std::vector<char>(valid, valid + num_nodes), std::move(idf));
}

void KeyframeDatabase::Add(int keyframe, const BowVector& bow) {
  for (const auto& [word, weight] : bow) keyframes_of_word_[word].emplace_back(keyframe, weight);
}

std::vector<KeyframeDatabase::Candidate> KeyframeDatabase::Query(
    const BowVector& bow, const std::function<bool(int)>& accept, double min_score,
    int max_results) const {
  std::unordered_map<int, double> scores;
  for (const auto& [word, weight] : bow) {
    const auto it = keyframes_of_word_.find(word);
    if (it == keyframes_of_word_.end()) continue;
    for (const auto& [keyframe, other] : it->second) scores[keyframe] += std::min(weight, other);
  }
  std::vector<Candidate> candidates;
  for (const auto& [keyframe, score] : scores) {
    if (score >= min_score && accept(keyframe)) candidates.push_back({keyframe, score});
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return a.score > b.score || (a.score == b.score && a.keyframe < b.keyframe);
  });
  if (static_cast<int>(candidates.size()) > max_results) candidates.resize(max_results);
  return candidates;
}

}  // namespace omnirig::slam
