#include "engine/geometry/ply_preview.h"

#include <algorithm>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// What the preview needs of a PLY header: its lines, the vertex line's index, the vertex count
// and record size; nullopt when the body is not a plain array of fixed-size vertices.
struct PlyLayout {
  std::vector<std::string> lines;  // without "end_header"
  size_t vertex_line = 0;
  int64_t num_vertices = 0;
  int64_t vertex_bytes = 0;
  int64_t header_bytes = 0;  // through "end_header\n"
};

int ScalarBytes(const std::string& type) {
  static const std::map<std::string, int> kBytes = {
      {"char", 1},   {"int8", 1},    {"uchar", 1},  {"uint8", 1},  {"short", 2}, {"int16", 2},
      {"ushort", 2}, {"uint16", 2},  {"int", 4},    {"int32", 4},  {"uint", 4},  {"uint32", 4},
      {"float", 4},  {"float32", 4}, {"double", 8}, {"float64", 8}};
  const auto it = kBytes.find(type);
  return it == kBytes.end() ? 0 : it->second;
}

std::optional<PlyLayout> ReadLayout(std::istream& in) {
  PlyLayout layout;
  std::string line;
  bool binary = false, in_vertex = false, seen_vertex = false;
  while (std::getline(in, line)) {
    layout.header_bytes += static_cast<int64_t>(line.size()) + 1;
    if (!line.empty() && line.back() == '\r') return std::nullopt;  // CRLF headers: left alone
    if (line == "end_header") break;
    if (layout.lines.empty() && line != "ply") return std::nullopt;
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "format") {
      std::string format;
      words >> format;
      binary = format == "binary_little_endian" || format == "binary_big_endian";
    } else if (keyword == "element") {
      std::string name;
      words >> name;
      if (name != "vertex" || seen_vertex) return std::nullopt;
      if (!(words >> layout.num_vertices) || layout.num_vertices < 0) return std::nullopt;
      layout.vertex_line = layout.lines.size();
      in_vertex = seen_vertex = true;
    } else if (keyword == "property") {
      std::string type;
      words >> type;
      const int bytes = ScalarBytes(type);
      if (!in_vertex || bytes == 0) return std::nullopt;  // a list, or an unknown type
      layout.vertex_bytes += bytes;
    }
    layout.lines.push_back(line);
  }
  if (line != "end_header" || !binary || !seen_vertex || layout.vertex_bytes == 0) {
    return std::nullopt;
  }
  return layout;
}

// Copies a random subset of `keep` of the layout's vertices from `in` (at the body) to `out`:
// selection sampling (Knuth's algorithm S), one pass, in order.
void CopySubset(std::istream& in, std::ostream& out, const PlyLayout& layout, int64_t keep,
                uint64_t seed, const std::filesystem::path& cloud) {
  constexpr int64_t kChunkVertices = 1 << 16;
  std::vector<char> chunk(static_cast<size_t>(kChunkVertices * layout.vertex_bytes));
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  int64_t kept = 0;
  for (int64_t first = 0; first < layout.num_vertices; first += kChunkVertices) {
    const int64_t n = std::min(kChunkVertices, layout.num_vertices - first);
    in.read(chunk.data(), n * layout.vertex_bytes);
    if (in.gcount() != n * layout.vertex_bytes) {
      throw std::runtime_error(cloud.string() + " holds fewer vertices than its header's " +
                               std::to_string(layout.num_vertices));
    }
    for (int64_t i = 0; i < n && kept < keep; ++i) {
      const int64_t left = layout.num_vertices - (first + i);
      if (uniform(random) * static_cast<double>(left) >= static_cast<double>(keep - kept)) continue;
      out.write(chunk.data() + i * layout.vertex_bytes, layout.vertex_bytes);
      ++kept;
    }
  }
}

}  // namespace

void PlyPreviewOptions::Check() const {
  OMNIRIG_CHECK_AT_LEAST(max_points, 1);
  OMNIRIG_CHECK_AT_LEAST(max_bytes, 1024);
}

std::filesystem::path PlyPreviewPath(const std::filesystem::path& cloud) {
  std::filesystem::path preview = cloud;
  preview.replace_extension(".preview.ply");
  return preview;
}

bool IsPlyPreviewPath(const std::filesystem::path& path) {
  const std::string name = path.filename().string();
  const std::string suffix = ".preview.ply";
  return name.size() > suffix.size() &&
         name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::optional<PlyPreview> WritePlyPreview(const std::filesystem::path& cloud,
                                          const PlyPreviewOptions& options) {
  options.Check();
  std::ifstream in(cloud, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + cloud.string());
  const std::optional<PlyLayout> layout = ReadLayout(in);
  if (!layout) return std::nullopt;
  const int64_t file_bytes = layout->header_bytes + layout->num_vertices * layout->vertex_bytes;
  if (layout->num_vertices <= options.max_points && file_bytes <= options.max_bytes) {
    return std::nullopt;
  }
  // The new header: the old one with the new count and a comment saying what the file is.
  const int64_t header_room =
      layout->header_bytes + 96 + static_cast<int64_t>(cloud.filename().string().size());
  const int64_t keep = std::max<int64_t>(
      1, std::min({options.max_points, (options.max_bytes - header_room) / layout->vertex_bytes,
                   layout->num_vertices}));
  std::string header;
  for (size_t i = 0; i < layout->lines.size(); ++i) {
    header +=
        i == layout->vertex_line ? "element vertex " + std::to_string(keep) : layout->lines[i];
    header += "\n";
    if (layout->lines[i].rfind("format ", 0) == 0) {
      header += "comment preview: " + std::to_string(keep) + " of " +
                std::to_string(layout->num_vertices) + " points of " + cloud.filename().string() +
                ", a random subset\n";
    }
  }
  header += "end_header\n";
  const std::filesystem::path preview = PlyPreviewPath(cloud);
  // Written under a temporary name (".NAME.part-preview", which the job's artifact listing
  // skips), then renamed: a preview is whole or absent.
  const std::filesystem::path partial =
      preview.parent_path() / ("." + preview.filename().string() + ".part-preview");
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    if (!out) throw std::runtime_error("cannot write " + partial.string());
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    CopySubset(in, out, *layout, keep, options.seed, cloud);
    out.flush();
    if (!out) throw std::runtime_error("cannot write " + partial.string());
  }
  std::filesystem::rename(partial, preview);
  return PlyPreview{preview, layout->num_vertices, keep};
}

std::vector<PlyPreview> WritePlyPreviews(const std::filesystem::path& dir,
                                         const PlyPreviewOptions& options) {
  std::vector<std::filesystem::path> clouds;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir)) {
    const std::filesystem::path& path = entry.path();
    if (entry.is_regular_file() && path.extension() == ".ply" && !IsPlyPreviewPath(path) &&
        path.filename().string().front() != '.') {
      clouds.push_back(path);
    }
  }
  std::sort(clouds.begin(), clouds.end());
  std::vector<PlyPreview> previews;
  for (const std::filesystem::path& cloud : clouds) {
    if (auto preview = WritePlyPreview(cloud, options)) previews.push_back(*preview);
  }
  return previews;
}

}  // namespace omnirig
