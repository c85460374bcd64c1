// DefaultVocabulary(): the vocabulary compiled into the library (vocabulary_data.cc is
// generated from engine/slam/data/vocabulary.bin by embed_file.cmake).

#include <cstddef>
#include <cstdint>

#include "engine/slam/vocabulary.h"
#include "engine/util/check.h"

namespace omnirig::slam {

extern const std::uint8_t kVocabularyData[];
extern const std::size_t kVocabularyData_size;

const Vocabulary& DefaultVocabulary() {
  static const Vocabulary vocabulary = [] {
    OMNIRIG_CHECK(kVocabularyData_size > 0,
                  "no vocabulary compiled in: train one with bench/train_vocabulary");
    return Vocabulary::Deserialize(kVocabularyData, kVocabularyData_size);
  }();
  return vocabulary;
}

}  // namespace omnirig::slam
