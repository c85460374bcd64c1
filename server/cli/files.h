#pragma once
// A subcommand's files: a JSON file named by a flag, a stereo folder's image pairs, and writing
// an output file.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace omnirig::cli {

// The JSON document in `path`; InvalidArgument naming `flag` when it cannot be read or parsed.
nlohmann::json ReadJsonFile(const std::string& path, const std::string& flag);
// Writes `text` to `path`; InvalidArgument when it cannot.
void WriteFile(const std::string& path, const std::string& text);

// "cam0/NAME" and "cam1/NAME" for every image file (by extension) in DIR/cam0 and DIR/cam1,
// sorted; the jobs pair them by NAME and report images without a partner. InvalidArgument when
// DIR, DIR/cam0 or DIR/cam1 is missing.
std::vector<std::string> ListPairImages(const std::filesystem::path& dir);
// The names of the regular files directly in DIR, sorted (e.g. a recording's videos).
std::vector<std::string> ListFiles(const std::filesystem::path& dir);

}  // namespace omnirig::cli
