#include "testing/recordings/test_recordings.h"

#include <unistd.h>

#include <cstdlib>
#include <random>
#include <stdexcept>
#include <string>

namespace omnirig::testing {
namespace {

class WrittenRecordings {
 public:
  WrittenRecordings() {
    const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
    if (!source) throw std::runtime_error("OMNIRIG_SOURCE_DIR is not set (ctest sets it)");
    std::random_device seed;
    dir_ = std::filesystem::temp_directory_path() /
           ("omnirig-recordings-" + std::to_string(::getpid()) + "-" + std::to_string(seed()));
    const std::string command = std::string(source) + "/testing/recordings/write_all.sh '" +
                                dir_.string() + "' >&2";
    if (std::system(command.c_str()) != 0) {
      throw std::runtime_error("writing the test recordings failed: " + command);
    }
  }
  ~WrittenRecordings() {
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

}  // namespace

const std::filesystem::path& TestRecordingsDir() {
  static const WrittenRecordings recordings;
  return recordings.dir();
}

}  // namespace omnirig::testing
