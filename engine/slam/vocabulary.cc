#include "engine/slam/vocabulary.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>

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

}  // namespace

double BowScore(const BowVector& a, const BowVector& b) {
  double score = 0;
  auto i = a.begin();
  auto j = b.begin();
  while (i != a.end() && j != b.end()) {
    if (i->first < j->first) {
      ++i;
    } else if (j->first < i->first) {
      ++j;
    } else {
      score += std::min(i->second, j->second);
      ++i;
      ++j;
    }
  }
  return score;
}

int Vocabulary::NumNodes() const {
  return (Power(branching_, depth_ + 1) - 1) / (branching_ - 1);
}

int Vocabulary::FirstLeaf() const { return (Power(branching_, depth_) - 1) / (branching_ - 1); }

void Vocabulary::SplitNode(const cv::Mat& all, const NodeRows& node, std::vector<NodeRows>* next) {
  const auto& [parent, rows] = node;
  cv::Mat samples(static_cast<int>(rows.size()), kDescriptorSize, CV_32F);
  for (size_t i = 0; i < rows.size(); ++i) {
    all.row(rows[i]).copyTo(samples.row(static_cast<int>(i)));
  }
  cv::Mat labels, centres;
  const int k = std::min<int>(branching_, samples.rows);
  if (k == 0) return;
  if (k < branching_) {
    centres = samples.clone();
    labels = cv::Mat(samples.rows, 1, CV_32S);
    for (int i = 0; i < samples.rows; ++i) labels.at<int>(i) = i;
  } else {
    cv::kmeans(samples, k, labels,
               cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 15, 0.5), 1,
               cv::KMEANS_PP_CENTERS, centres);
  }
  for (int c = 0; c < k; ++c) {
    const int child = parent * branching_ + 1 + c;
    valid_[child] = 1;
    for (int i = 0; i < kDescriptorSize; ++i) {
      centres_[static_cast<std::size_t>(child) * kDescriptorSize + i] =
          cv::saturate_cast<std::uint8_t>(centres.at<float>(c, i));
    }
    next->push_back({child, {}});
  }
  const size_t first = next->size() - k;
  for (int i = 0; i < labels.rows; ++i) {
    (*next)[first + labels.at<int>(i)].second.push_back(rows[i]);
  }
}

void Vocabulary::SetIdf(const std::vector<cv::Mat>& images) {
  const int num_words = Power(branching_, depth_);
  idf_.assign(num_words, 1.0f);  // Word() needs a non-empty vocabulary
  std::vector<int> images_with(num_words, 0);
  for (const cv::Mat& d : images) {
    cv::Mat f;
    d.convertTo(f, CV_32F);
    std::set<int> words;
    for (int r = 0; r < f.rows; ++r) words.insert(Word(f.ptr<float>(r)));
    for (int w : words) ++images_with[w];
  }
  const double n = static_cast<double>(images.size());
  for (int w = 0; w < num_words; ++w) {
    idf_[w] = static_cast<float>(std::log(n / std::max(1, images_with[w])));
  }
}

Vocabulary Vocabulary::Train(const std::vector<cv::Mat>& images, int branching, int depth,
                             std::uint64_t seed) {
  OMNIRIG_CHECK(branching >= 2 && depth >= 1 && Power(branching, depth) <= (1 << 20),
                "a vocabulary needs branching >= 2, depth >= 1 and at most 2^20 words");
  cv::Mat all;
  for (const cv::Mat& d : images) {
    OMNIRIG_CHECK(d.cols == kDescriptorSize, "vocabulary training needs SIFT descriptors");
    cv::Mat f;
    d.convertTo(f, CV_32F);
    all.push_back(f);
  }
  OMNIRIG_CHECK(all.rows >= branching, "too few descriptors to train a vocabulary");
  Vocabulary vocabulary;
  vocabulary.branching_ = branching;
  vocabulary.depth_ = depth;
  const int num_nodes = vocabulary.NumNodes();
  vocabulary.centres_.assign(static_cast<std::size_t>(num_nodes) * kDescriptorSize, 0);
  vocabulary.valid_.assign(num_nodes, 0);
  vocabulary.valid_[0] = 1;
  cv::theRNG().state = seed == 0 ? 1 : seed;
  // Breadth first: the descriptors of each node of the current level.
  std::vector<NodeRows> level = {{0, {}}};
  for (int r = 0; r < all.rows; ++r) level[0].second.push_back(r);
  for (int d = 0; d < depth; ++d) {
    std::vector<NodeRows> next;
    for (const NodeRows& node : level) vocabulary.SplitNode(all, node, &next);
    level = std::move(next);
  }
  // idf from the rounded centres, as Word() will see them.
  vocabulary.SetIdf(images);
  return vocabulary;
}

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
  Vocabulary vocabulary;
  vocabulary.branching_ = static_cast<int>(header[1]);
  vocabulary.depth_ = static_cast<int>(header[2]);
  OMNIRIG_CHECK(vocabulary.branching_ >= 2 && vocabulary.depth_ >= 1 &&
                    Power(vocabulary.branching_, vocabulary.depth_) <= (1 << 20),
                "vocabulary: invalid tree shape");
  const std::size_t num_nodes = vocabulary.NumNodes();
  const std::size_t num_words = Power(vocabulary.branching_, vocabulary.depth_);
  const std::size_t expected =
      sizeof(header) + num_nodes * (1 + kDescriptorSize) + num_words * sizeof(float);
  OMNIRIG_CHECK(size == expected, "vocabulary: " << size << " bytes, expected " << expected);
  const std::uint8_t* p = data + sizeof(header);
  vocabulary.valid_.assign(p, p + num_nodes);
  p += num_nodes;
  vocabulary.centres_.assign(p, p + num_nodes * kDescriptorSize);
  p += num_nodes * kDescriptorSize;
  vocabulary.idf_.resize(num_words);
  std::memcpy(vocabulary.idf_.data(), p, num_words * sizeof(float));
  return vocabulary;
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
