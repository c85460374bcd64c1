// The loop-closure pose graph (pose_graph.cc): a square driven around with a drifting heading
// comes back to its start once the loop edge joins the ends.

#include <cmath>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "engine/slam/pose_graph.h"
#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

Rigid3d Pose(double x, double y, double yaw) {  // world_from_rig
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(x, y, 0));
}

TEST(PoseGraph, ALoopEdgeRemovesTheDriftOfASquare) {
  // Truth: 16 poses around a 4 m square; odometry with 1 degree of heading drift per step.
  std::vector<Rigid3d> truth;
  for (int i = 0; i < 16; ++i) {
    const int side = i / 4, k = i % 4;
    const double yaw = side * M_PI / 2;
    const Eigen::Vector2d corner[4] = {{0, 0}, {4, 0}, {4, 4}, {0, 4}};
    const Eigen::Vector2d step = Eigen::Vector2d(std::cos(yaw), std::sin(yaw));
    const Eigen::Vector2d p = corner[side] + k * step;
    truth.push_back(Pose(p.x(), p.y(), yaw));
  }
  const Rigid3d drift(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 180, Eigen::Vector3d::UnitZ())),
                      Eigen::Vector3d::Zero());
  std::map<int, Rigid3d> rig_from_world;
  std::vector<PoseGraphEdge> edges;
  Rigid3d world_from_rig = truth[0];
  rig_from_world[0] = world_from_rig.Inverse();
  for (int i = 1; i < 16; ++i) {
    const Rigid3d step = truth[i - 1].Inverse() * truth[i];  // prev_from_curr
    world_from_rig = world_from_rig * drift * step;
    rig_from_world[i] = world_from_rig.Inverse();
    edges.push_back({i - 1, i, rig_from_world[i] * rig_from_world[i - 1].Inverse()});
  }
  // The loop: pose 15 seen from pose 0 as it truly is.
  edges.push_back({0, 15, truth[15].Inverse() * truth[0]});
  const double before = (rig_from_world[15].Inverse().translation - truth[15].translation).norm();
  const PoseGraphReport report = OptimisePoseGraph(edges, {0}, 1, &rig_from_world);
  const double after = (rig_from_world[15].Inverse().translation - truth[15].translation).norm();
  EXPECT_GT(before, 0.5);
  EXPECT_LT(after, 0.05);
  EXPECT_LT(report.solver.final_cost, report.solver.initial_cost);
  EXPECT_EQ(report.num_poses, 16);
  EXPECT_LT((rig_from_world[0].Inverse().translation - truth[0].translation).norm(), 1e-12);
}

TEST(PoseGraph, RefusesAGraphWithoutGaugeOrWithUnknownPoses) {
  std::map<int, Rigid3d> poses = {{0, Rigid3d()}, {1, Rigid3d()}};
  EXPECT_THROW(OptimisePoseGraph({{0, 1, Rigid3d()}}, {}, 1, &poses), InvalidArgument);
  EXPECT_THROW(OptimisePoseGraph({{0, 2, Rigid3d()}}, {0}, 1, &poses), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::slam
