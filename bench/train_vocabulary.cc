// train_vocabulary: trains the bag-of-words vocabulary that SLAM's place recognition ships with
// (engine/slam/data/vocabulary.bin, compiled into the library; see engine/slam/vocabulary.h).
// Run once; the output is committed. It renders cam0 images of scenes and seeds that no test or
// benchmark uses (room and street of seeds 101-102), detects SIFT inside the mirror as SLAM
// does, and clusters the descriptors into a tree of `branching`^`depth` words.
//
// usage: train_vocabulary OUTPUT [--frames N] [--branching K] [--depth L]

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "engine/features/features.h"
#include "engine/slam/vocabulary.h"
#include "engine/synth/presets.h"
#include "engine/util/timer.h"
#include "testing/slam/vocabulary_training.h"

namespace omnirig {
namespace {

// SIFT descriptors of cam0 of every frame of one rendered sequence, as SLAM detects them.
void AddSequence(synth::StereoSequenceOptions::Environment environment, std::uint64_t seed,
                 int frames, std::vector<cv::Mat>* images) {
  synth::StereoSequenceOptions options;
  options.environment = environment;
  options.seed = seed;
  options.num_frames = frames;
  options.render.noise_sigma = 1.0;
  options.render.supersampling = 2;
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  const FeatureOptions features;
  const CameraModel& camera = sequence.rig.cam0;
  const cv::Mat mask =
      MirrorMask(sequence.images[0][0], PrincipalPoint(camera), features.mirror_mask);
  for (const cv::Mat& image : sequence.images[0]) {
    images->push_back(DetectFeatures(camera, image, mask, features).descriptors);
  }
}

int Run(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: train_vocabulary OUTPUT [--frames N] [--branching K] [--depth L]\n");
    return 2;
  }
  int frames = 30, branching = 10, depth = 3;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--frames") frames = std::atoi(argv[i + 1]);
    if (a == "--branching") branching = std::atoi(argv[i + 1]);
    if (a == "--depth") depth = std::atoi(argv[i + 1]);
  }
  const Timer timer;
  std::vector<cv::Mat> images;
  using Environment = synth::StereoSequenceOptions::Environment;
  for (std::uint64_t seed : {101, 102}) {
    AddSequence(Environment::kRoom, seed, frames, &images);
    AddSequence(Environment::kStreet, seed, frames, &images);
  }
  int descriptors = 0;
  for (const cv::Mat& d : images) descriptors += d.rows;
  std::printf("%zu images, %d descriptors (%.1f s)\n", images.size(), descriptors,
              timer.ElapsedSeconds());
  const slam::Vocabulary vocabulary = slam::TrainVocabulary(images, branching, depth, 1);
  const std::vector<std::uint8_t> bytes = vocabulary.Serialize();
  std::ofstream out(argv[1], std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  std::printf("%d words, %zu bytes written to %s (%.1f s)\n", vocabulary.num_words(), bytes.size(),
              argv[1], timer.ElapsedSeconds());
  return out ? 0 : 1;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) { return omnirig::Run(argc, argv); }
