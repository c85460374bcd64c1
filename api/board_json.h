#pragma once
// The "board" object of the jobs that detect a calibration board (calibration, relative_pose):
//   {"type": "checkerboard" | "charuco" (default checkerboard), "cols", "rows" (inner corners),
//    "square_size_mm", "marker_size_mm" (charuco; optional otherwise), "aruco_dictionary"}
//   {"type": "aprilgrid", "tag_cols", "tag_rows", "tag_size_m", "tag_spacing"} (Kalibr's
//    AprilGrid, tag family 36h11; tag_spacing is the gap between tags over the tag size)
// or, in place of the object, the name of a Kalibr target YAML among the dataset's files
// ("board": "aprilgrid.yaml"), read when the job runs.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/calib/board.h"
#include "engine/geometry/camera_model.h"

namespace omnirig::api {

// Throws InvalidArgument naming the field ("board.cols", ...) for unknown fields, wrong types
// and a board that fails BoardSpec::Check.
BoardSpec BoardFromJson(const nlohmann::json& board);

// "params.board" as an object (into *board) or the name of a .yaml file of the dataset (into
// *kalibr_target_file, *board left as it is). Throws InvalidArgument as BoardFromJson does.
void ReadBoardParam(const nlohmann::json& params, BoardSpec* board,
                    std::string* kalibr_target_file);

// The board of a Kalibr target file of the dataset (throws InvalidArgument naming the file and
// what is wrong with it).
BoardSpec ReadKalibrTargetFile(const std::filesystem::path& dataset_dir, const std::string& name);

// At submission: a named target file is among the dataset's files (throws InvalidArgument
// listing the dataset's .yaml files otherwise). Nothing to check for an empty name.
void CheckKalibrTargetFileIn(const std::string& name, const std::vector<std::string>& file_names);

// The name of a .yaml file of the dataset given in `field` (e.g. "params.calibrations"), `what`
// naming what it must hold in the message ("a Kalibr camchain"). Throws InvalidArgument for a
// value that is not such a name.
std::string DatasetYamlName(const nlohmann::json& value, const std::string& field,
                            const std::string& what);

// At submission: `name` (from `field`) is among the dataset's files; throws InvalidArgument
// listing the dataset's .yaml files otherwise. Nothing to check for an empty name.
void CheckDatasetFileIn(const std::string& name, const std::string& field,
                        const std::vector<std::string>& file_names);

// The two cameras and the extrinsic of a Kalibr camchain of the dataset (omni-radtan; throws
// InvalidArgument naming the file and what is wrong with it).
StereoRig ReadKalibrCamchainFile(const std::filesystem::path& dataset_dir, const std::string& name);

// True for the dataset's files that are not images of a board (.tum trajectories, .yaml
// targets and camera chains), which the board-detecting jobs leave out.
bool IsSideFile(const std::string& name);

}  // namespace omnirig::api
