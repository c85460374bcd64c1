#pragma once
// bench_slam --loop: SLAM on long closed loops around the synthetic city block (against
// their targets). See slam_loop_bench.cc for what it measures.

namespace omnirig {

// Runs the loop bench with bench_slam's command line; returns the process's exit code.
int RunLoopBench(int argc, char** argv);

}  // namespace omnirig
