#include "testing/slam/vocabulary_training.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

constexpr int kDescriptorSize = Vocabulary::kDescriptorSize;

// The descriptors of a node of the tree being trained (rows of the training matrix).
using NodeRows = std::pair<int, std::vector<int>>;

// The tree being trained, in the layout Vocabulary's constructor takes.
struct Tree {
  int branching = 0;
  std::vector<std::uint8_t> centres;
  std::vector<char> valid;
};

// Clusters a node's descriptors into its children (k-means, or one child per descriptor when
// fewer than `branching`), appending the children to `next`.
void SplitNode(const cv::Mat& all, const NodeRows& node, Tree* tree, std::vector<NodeRows>* next) {
  const auto& [parent, rows] = node;
  cv::Mat samples(static_cast<int>(rows.size()), kDescriptorSize, CV_32F);
  for (size_t i = 0; i < rows.size(); ++i) {
    all.row(rows[i]).copyTo(samples.row(static_cast<int>(i)));
  }
  cv::Mat labels, centres;
  const int k = std::min<int>(tree->branching, samples.rows);
  if (k == 0) return;
  if (k < tree->branching) {
    centres = samples.clone();
    labels = cv::Mat(samples.rows, 1, CV_32S);
    for (int i = 0; i < samples.rows; ++i) labels.at<int>(i) = i;
  } else {
    cv::kmeans(samples, k, labels,
               cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 15, 0.5), 1,
               cv::KMEANS_PP_CENTERS, centres);
  }
  for (int c = 0; c < k; ++c) {
    const int child = parent * tree->branching + 1 + c;
    tree->valid[child] = 1;
    for (int i = 0; i < kDescriptorSize; ++i) {
      tree->centres[static_cast<std::size_t>(child) * kDescriptorSize + i] =
          cv::saturate_cast<std::uint8_t>(centres.at<float>(c, i));
    }
    next->push_back({child, {}});
  }
  const size_t first = next->size() - k;
  for (int i = 0; i < labels.rows; ++i) {
    (*next)[first + labels.at<int>(i)].second.push_back(rows[i]);
  }
}

// idf per word from the images' descriptors, as `vocabulary`'s Word() assigns them.
std::vector<float> Idf(const Vocabulary& vocabulary, const std::vector<cv::Mat>& images) {
  const int num_words = vocabulary.num_words();
  std::vector<int> images_with(num_words, 0);
  for (const cv::Mat& d : images) {
    cv::Mat f;
    d.convertTo(f, CV_32F);
    std::set<int> words;
    for (int r = 0; r < f.rows; ++r) words.insert(vocabulary.Word(f.ptr<float>(r)));
    for (int w : words) ++images_with[w];
  }
  std::vector<float> idf(num_words);
  const double n = static_cast<double>(images.size());
  for (int w = 0; w < num_words; ++w) {
    idf[w] = static_cast<float>(std::log(n / std::max(1, images_with[w])));
  }
  return idf;
}

}  // namespace

Vocabulary TrainVocabulary(const std::vector<cv::Mat>& images, int branching, int depth,
                           std::uint64_t seed) {
  OMNIRIG_CHECK(branching >= 2 && depth >= 1 && std::pow(branching, depth) <= (1 << 20),
                "a vocabulary needs branching >= 2, depth >= 1 and at most 2^20 words");
  int num_words = 1, num_nodes = 1;
  for (int d = 0; d < depth; ++d) {
    num_words *= branching;
    num_nodes += num_words;
  }
  cv::Mat all;
  for (const cv::Mat& d : images) {
    OMNIRIG_CHECK(d.cols == kDescriptorSize, "vocabulary training needs SIFT descriptors");
    cv::Mat f;
    d.convertTo(f, CV_32F);
    all.push_back(f);
  }
  OMNIRIG_CHECK(all.rows >= branching, "too few descriptors to train a vocabulary");
  Tree tree{branching,
            std::vector<std::uint8_t>(static_cast<std::size_t>(num_nodes) * kDescriptorSize, 0),
            std::vector<char>(num_nodes, 0)};
  tree.valid[0] = 1;
  cv::theRNG().state = seed == 0 ? 1 : seed;
  // Breadth first: the descriptors of each node of the current level.
  std::vector<NodeRows> level = {{0, {}}};
  for (int r = 0; r < all.rows; ++r) level[0].second.push_back(r);
  for (int d = 0; d < depth; ++d) {
    std::vector<NodeRows> next;
    for (const NodeRows& node : level) SplitNode(all, node, &tree, &next);
    level = std::move(next);
  }
  // idf from the rounded centres, as Word() will see them (Word() needs a non-empty idf).
  const Vocabulary unweighted(branching, depth, tree.centres, tree.valid,
                              std::vector<float>(num_words, 1.0f));
  return Vocabulary(branching, depth, std::move(tree.centres), std::move(tree.valid),
                    Idf(unweighted, images));
}

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

}  // namespace omnirig::slam
