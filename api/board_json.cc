#include "api/board_json.h"

#include <fstream>
#include <sstream>

#include "api/json_fields.h"
#include "engine/calib/model_io.h"
#include "engine/util/check.h"
#include "engine/util/error_prefix.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

bool EndsWith(const std::string& text, const std::string& suffix) {
  return text.size() > suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool IsYamlName(const std::string& name) {
  return EndsWith(name, ".yaml") || EndsWith(name, ".yml");
}

BoardSpec AprilgridFromJson(const json& board) {
  CheckKnownFields(board, "board", {"type", "tag_cols", "tag_rows", "tag_size_m", "tag_spacing"});
  const int tag_cols = IntegerField(board, "board", "tag_cols");
  const int tag_rows = IntegerField(board, "board", "tag_rows");
  OMNIRIG_CHECK(tag_cols >= 1 && tag_rows >= 1 && tag_cols <= 50 && tag_rows <= 50,
                "fields 'board.tag_cols' and 'board.tag_rows' must be in [1, 50], got "
                    << tag_cols << " and " << tag_rows);
  return BoardSpec::Aprilgrid(tag_cols, tag_rows, NumberField(board, "board", "tag_size_m"),
                              NumberField(board, "board", "tag_spacing"));
}

}  // namespace

BoardSpec BoardFromJson(const json& board) {
  OMNIRIG_CHECK(board.is_object(), "field 'params.board' must be an object or the name of a "
                                   "Kalibr target .yaml file of the dataset");
  const auto type = board.find("type");
  BoardSpec spec;
  if (type != board.end() && *type == "aprilgrid") {
    spec = AprilgridFromJson(board);
  } else {
    CheckKnownFields(
        board, "board",
        {"type", "cols", "rows", "square_size_mm", "marker_size_mm", "aruco_dictionary"});
    if (type != board.end()) {
      OMNIRIG_CHECK(type->is_string() && (*type == "checkerboard" || *type == "charuco"),
                    "field 'board.type' must be \"checkerboard\", \"charuco\" or \"aprilgrid\"");
      spec.type = *type == "charuco" ? BoardSpec::Type::kCharuco : BoardSpec::Type::kCheckerboard;
    }
    spec.cols = IntegerField(board, "board", "cols");
    spec.rows = IntegerField(board, "board", "rows");
    spec.square_size_m = NumberField(board, "board", "square_size_mm") * 1e-3;
    const bool charuco = spec.type == BoardSpec::Type::kCharuco;
    const bool has_marker = charuco || board.contains("marker_size_mm");
    spec.marker_size_m = has_marker ? NumberField(board, "board", "marker_size_mm") * 1e-3 : 0.0;
    ReadInteger(board, "board", "aruco_dictionary", &spec.aruco_dictionary);
  }
  WithErrorPrefix("field 'board': ", [&] { spec.Check(); });
  return spec;
}

std::string DatasetYamlName(const json& value, const std::string& field, const std::string& what) {
  const std::string name = value.is_string() ? value.get<std::string>() : std::string();
  OMNIRIG_CHECK(IsYamlName(name) && name.find("..") == std::string::npos && name[0] != '/',
                "field '" << field << "' names " << what
                          << " file of the dataset, which must be a .yaml file, got "
                          << value.dump());
  return name;
}

void ReadBoardParam(const json& params, BoardSpec* board, std::string* kalibr_target_file) {
  const json& value = Field(params, "params", "board");
  if (value.is_string()) {
    *kalibr_target_file = DatasetYamlName(value, "params.board", "a Kalibr target");
  } else {
    *board = BoardFromJson(value);
  }
}

namespace {

std::string ReadDatasetFile(const std::filesystem::path& dataset_dir, const std::string& name) {
  std::ifstream file(dataset_dir / name, std::ios::binary);
  OMNIRIG_CHECK(file, "the dataset has no file '" << name << "'");
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

}  // namespace

BoardSpec ReadKalibrTargetFile(const std::filesystem::path& dataset_dir, const std::string& name) {
  return WithErrorPrefix("board '" + name + "': ",
                         [&] { return BoardFromKalibrTarget(ReadDatasetFile(dataset_dir, name)); });
}

StereoRig ReadKalibrCamchainFile(const std::filesystem::path& dataset_dir,
                                 const std::string& name) {
  return WithErrorPrefix("calibrations '" + name + "': ", [&] {
    const StereoRig rig = FromKalibrCamchain(ReadDatasetFile(dataset_dir, name));
    OMNIRIG_CHECK(rig.cam0.width > 0 && rig.cam1.width > 0,
                  "each camera needs its 'resolution' (the images' size in pixels)");
    return rig;
  });
}

void CheckDatasetFileIn(const std::string& name, const std::string& field,
                        const std::vector<std::string>& file_names) {
  if (name.empty()) return;
  std::string yaml_files;
  for (const std::string& file : file_names) {
    if (file == name) return;
    if (IsYamlName(file)) yaml_files += (yaml_files.empty() ? "" : ", ") + file;
  }
  OMNIRIG_CHECK(false, "field '" << field << "' names '" << name
                                 << "', which the dataset does not hold ("
                                 << (yaml_files.empty() ? "it has no .yaml file"
                                                        : "its .yaml files: " + yaml_files)
                                 << "); upload it beside the images");
}

void CheckKalibrTargetFileIn(const std::string& name, const std::vector<std::string>& file_names) {
  CheckDatasetFileIn(name, "params.board", file_names);
}

bool IsSideFile(const std::string& name) { return IsYamlName(name) || EndsWith(name, ".tum"); }

}  // namespace omnirig::api
