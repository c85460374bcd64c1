// The bag of words (vocabulary.cc): training, the binary round trip, scores, the keyframe
// database, and the shipped vocabulary.

#include <random>

#include <gtest/gtest.h>

#include "engine/slam/vocabulary.h"
#include "engine/util/check.h"
#include "testing/slam/vocabulary_training.h"

namespace omnirig::slam {
namespace {

// `count` SIFT-like descriptors (integers in [0, 255]) around 2 of 8 patterns (offset and
// offset + 1): words that every image holds weigh nothing (idf 0).
cv::Mat Descriptors(int count, int offset, std::mt19937* rng) {
  std::uniform_int_distribution<int> word(0, 1), noise(-6, 6);
  cv::Mat d(count, Vocabulary::kDescriptorSize, CV_32F);
  for (int r = 0; r < count; ++r) {
    const int w = (word(*rng) + offset) % 8;
    for (int i = 0; i < Vocabulary::kDescriptorSize; ++i) {
      const int centre = ((i * 37 + w * 101) % 7 == 0) ? 200 : 20;
      d.at<float>(r, i) = static_cast<float>(centre + noise(*rng));
    }
  }
  return d;
}

TEST(Vocabulary, TrainsRoundTripsAndScoresTheSameImageHighest) {
  std::mt19937 rng(3);
  std::vector<cv::Mat> images;
  for (int k = 0; k < 6; ++k) images.push_back(Descriptors(200, k, &rng));
  const Vocabulary vocabulary = TrainVocabulary(images, 4, 2, 1);
  EXPECT_EQ(vocabulary.num_words(), 16);
  const std::vector<std::uint8_t> bytes = vocabulary.Serialize();
  const Vocabulary loaded = Vocabulary::Deserialize(bytes.data(), bytes.size());
  for (int r = 0; r < images[0].rows; ++r) {
    EXPECT_EQ(loaded.Word(images[0].ptr<float>(r)), vocabulary.Word(images[0].ptr<float>(r)));
  }
  const BowVector a = loaded.Transform(images[0]);
  double sum = 0;
  for (const auto& [word, weight] : a) sum += weight;
  EXPECT_NEAR(sum, 1.0, 1e-5);
  EXPECT_NEAR(BowScore(a, a), 1.0, 1e-5);
  EXPECT_EQ(BowScore(a, {}), 0.0);
  // Malformed blobs are refused.
  EXPECT_THROW(Vocabulary::Deserialize(bytes.data(), bytes.size() - 1), InvalidArgument);
  std::vector<std::uint8_t> bad = bytes;
  bad[0] ^= 1;
  EXPECT_THROW(Vocabulary::Deserialize(bad.data(), bad.size()), InvalidArgument);
  // A tree's arrays must fit its shape.
  EXPECT_THROW(Vocabulary(4, 2, {}, {}, {}), InvalidArgument);
  EXPECT_THROW(Vocabulary(1, 2, {}, {}, {}), InvalidArgument);
}

TEST(KeyframeDatabase, ReturnsAcceptedKeyframesBestFirst) {
  KeyframeDatabase database;
  database.Add(10, {{1, 0.5f}, {2, 0.5f}});
  database.Add(20, {{1, 0.25f}, {3, 0.75f}});
  database.Add(30, {{4, 1.0f}});
  const BowVector query = {{1, 0.5f}, {2, 0.5f}};
  const auto all = database.Query(query, [](int) { return true; }, 0.0, 5);
  ASSERT_EQ(all.size(), 2u);  // keyframe 30 shares no word
  EXPECT_EQ(all[0].keyframe, 10);
  EXPECT_NEAR(all[0].score, 1.0, 1e-6);
  EXPECT_EQ(all[1].keyframe, 20);
  EXPECT_NEAR(all[1].score, 0.25, 1e-6);
  EXPECT_TRUE(database.Query(query, [](int k) { return k != 10; }, 0.5, 5).empty());
}

TEST(DefaultVocabulary, IsCompiledInWithAThousandWords) {
  EXPECT_EQ(DefaultVocabulary().num_words(), 1000);
}

TEST(Vocabulary, NodesHoldTheirWordsAndTransformReportsEachRowsWord) {
  std::mt19937 rng(4);
  std::vector<cv::Mat> images;
  for (int k = 0; k < 6; ++k) images.push_back(Descriptors(200, k, &rng));
  const Vocabulary vocabulary = TrainVocabulary(images, 4, 2, 1);
  // 16 words under 4 nodes of level 1: word w's path from the root is its base-4 digits.
  EXPECT_EQ(vocabulary.NodeOf(0, 1), 0);
  EXPECT_EQ(vocabulary.NodeOf(7, 1), 1);
  EXPECT_EQ(vocabulary.NodeOf(15, 1), 3);
  EXPECT_EQ(vocabulary.NodeOf(13, 2), 13);
  EXPECT_THROW(vocabulary.NodeOf(3, 3), InvalidArgument);
  std::vector<int> words;
  const BowVector bow = vocabulary.Transform(images[1], &words);
  ASSERT_EQ(words.size(), static_cast<size_t>(images[1].rows));
  for (int r = 0; r < images[1].rows; ++r) {
    EXPECT_EQ(words[r], vocabulary.Word(images[1].ptr<float>(r)));
  }
  EXPECT_EQ(bow, vocabulary.Transform(images[1]));
}

}  // namespace
}  // namespace omnirig::slam
