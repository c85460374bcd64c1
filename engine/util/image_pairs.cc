#include "engine/util/image_pairs.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>

#include "engine/util/check.h"

namespace omnirig {

std::vector<ImagePairNames> MatchImagePairs(const std::vector<std::string>& image_names) {
  std::map<std::string, std::string> cam0, cam1;
  for (const std::string& name : image_names) {
    if (name.rfind("cam0/", 0) == 0 && name.size() > 5) cam0[name.substr(5)] = name;
    if (name.rfind("cam1/", 0) == 0 && name.size() > 5) cam1[name.substr(5)] = name;
  }
  OMNIRIG_CHECK(!cam0.empty() && !cam1.empty(),
                "the dataset needs images named cam0/NAME and cam1/NAME (found "
                    << cam0.size() << " cam0/ and " << cam1.size() << " cam1/ images)");
  std::vector<std::string> missing;
  for (const auto& [name, path] : cam0) {
    if (cam1.count(name) == 0) missing.push_back(path + " has no cam1/" + name);
  }
  for (const auto& [name, path] : cam1) {
    if (cam0.count(name) == 0) missing.push_back(path + " has no cam0/" + name);
  }
  if (!missing.empty()) {
    std::ostringstream os;
    os << "images without a partner (pairs are matched by name):";
    for (const std::string& m : missing) os << " " << m << ";";
    throw InvalidArgument(os.str());
  }
  std::vector<ImagePairNames> pairs;
  for (const auto& [name, path] : cam0) pairs.push_back({name, path, cam1[name]});
  return pairs;
}

std::string FrameName(double timestamp_s) {
  char name[40];
  std::snprintf(name, sizeof(name), "t%010.3f", timestamp_s);
  return name;
}

std::optional<double> NameAsTimestamp(const std::string& name) {
  std::string stem = std::filesystem::path(name).stem().string();
  // A recording's frames are named "t" and the time (slam::FrameName, e.g. "t000012.345").
  if (stem.size() > 1 && stem[0] == 't') stem.erase(0, 1);
  char* end = nullptr;
  const double value = std::strtod(stem.c_str(), &end);
  if (stem.empty() || end != stem.c_str() + stem.size()) return std::nullopt;
  return value;
}

}  // namespace omnirig
