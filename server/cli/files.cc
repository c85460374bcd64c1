#include "server/cli/files.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <set>

#include "engine/util/check.h"

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;

bool IsImageFile(const fs::path& path) {
  static const std::set<std::string> kExtensions = {".png", ".jpg", ".jpeg", ".bmp",
                                                    ".tif", ".tiff", ".pgm", ".ppm"};
  std::string ext = path.extension().string();
  for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return kExtensions.count(ext) > 0;
}

}  // namespace

nlohmann::json ReadJsonFile(const std::string& path, const std::string& flag) {
  std::ifstream in(path);
  OMNIRIG_CHECK(in, flag << ": cannot read '" << path << "'");
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw InvalidArgument(flag + ": '" + path + "' is not JSON: " + e.what());
  }
}

void WriteFile(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  OMNIRIG_CHECK(out, "cannot write '" << path << "'");
  out << text;
  OMNIRIG_CHECK(out.good(), "cannot write '" << path << "'");
}

std::vector<std::string> ListPairImages(const fs::path& dir) {
  OMNIRIG_CHECK(fs::is_directory(dir), "'" << dir.string() << "' is not a directory");
  std::vector<std::string> names;
  for (const char* camera : {"cam0", "cam1"}) {
    const fs::path sub = dir / camera;
    OMNIRIG_CHECK(fs::is_directory(sub), "'" << sub.string()
                                             << "' is missing: DIR must hold cam0/ and cam1/");
    for (const auto& entry : fs::directory_iterator(sub)) {
      if (entry.is_regular_file() && IsImageFile(entry.path())) {
        names.push_back(std::string(camera) + "/" + entry.path().filename().string());
      }
    }
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::vector<std::string> ListFiles(const fs::path& dir) {
  OMNIRIG_CHECK(fs::is_directory(dir), "'" << dir.string() << "' is not a directory");
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.is_regular_file()) names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace omnirig::cli
