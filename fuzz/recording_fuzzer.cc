// A robot recording's bytes (storage/recording.h), uploaded as a file whose extension gives its
// container: OMNIRIG_FUZZ_RECORDING_EXTENSION (".bag", ".mcap" or ".db3"; compile definition,
// one target per container). The upload check and, for a whole recording, a read of every
// message: each either succeeds or throws RecordingError naming the file and what is wrong;
// any other exception, a crash or a read past the file is a failure here.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

#include "fuzz/fuzz_check.h"
#include "storage/recording.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace omnirig::storage;
  static const std::string name = std::string("fuzz") + OMNIRIG_FUZZ_RECORDING_EXTENSION;
  // The readers take a file (they map it); /dev/shm keeps it in memory.
  static const std::string path =
      "/dev/shm/omnirig-fuzz-" + std::to_string(::getpid()) + OMNIRIG_FUZZ_RECORDING_EXTENSION;
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    FUZZ_CHECK(out.good());
  }
  try {
    const std::optional<RecordingIndex> index = CheckRecordingFile(name, path);
    if (index) {
      const auto recording = Recording::Open(path, name);
      recording->ReadMessages({}, [&](const RecordingMessage& message) {
        FUZZ_CHECK(message.topic != nullptr);
        return true;
      });
    }
  } catch (const RecordingError& e) {
    FUZZ_CHECK(e.what()[0] != '\0');
  }
  return 0;
}
