#include "api/board_json.h"

#include "api/json_fields.h"
#include "engine/util/check.h"

namespace omnirig::api {

using nlohmann::json;

BoardSpec BoardFromJson(const json& board) {
  CheckKnownFields(
      board, "board",
      {"type", "cols", "rows", "square_size_mm", "marker_size_mm", "aruco_dictionary"});
  BoardSpec spec;
  const auto type = board.find("type");
  if (type != board.end()) {
    OMNIRIG_CHECK(type->is_string() && (*type == "checkerboard" || *type == "charuco"),
                  "field 'board.type' must be \"checkerboard\" or \"charuco\"");
    spec.type = *type == "charuco" ? BoardSpec::Type::kCharuco : BoardSpec::Type::kCheckerboard;
  }
  spec.cols = IntegerField(board, "board", "cols");
  spec.rows = IntegerField(board, "board", "rows");
  spec.square_size_m = NumberField(board, "board", "square_size_mm") * 1e-3;
  const bool charuco = spec.type == BoardSpec::Type::kCharuco;
  const bool has_marker = charuco || board.contains("marker_size_mm");
  spec.marker_size_m = has_marker ? NumberField(board, "board", "marker_size_mm") * 1e-3 : 0.0;
  ReadInteger(board, "board", "aruco_dictionary", &spec.aruco_dictionary);
  WithErrorPrefix("field 'board': ", [&] { spec.Check(); });
  return spec;
}

}  // namespace omnirig::api
