#pragma once
// Each subcommand registers its options on the CLI11 app and returns the function that runs it.
// Commands stay thin: parse options, call library code, print (human text on stderr, data on
// stdout with --json).
#include <functional>

#include <CLI/CLI.hpp>

namespace previz::app {

using Runner = std::function<int()>;

Runner addSynthCommand(CLI::App& app);
Runner addDemoCommand(CLI::App& app);
Runner addCameraCommand(CLI::App& app);
Runner addCalibCommand(CLI::App& app);
Runner addRigCommand(CLI::App& app);
// `previz calib lens`, registered under the calib command.
Runner addLensCommand(CLI::App& calib);
Runner addCarveCommand(CLI::App& app);
// `previz track` (with verbs `prop` and `camera`); defined only when tracking/ is built.
Runner addTrackCommand(CLI::App& app);
Runner addCompositeCommand(CLI::App& app);
Runner addRunCommand(CLI::App& app);
// `previz tracker record | replay | simulate | align` (live/tracker.h).
Runner addTrackerCommand(CLI::App& app);
// `previz bench run` (the bench command with its verbs).
Runner addBenchCommand(CLI::App& app);
Runner addBatchCommand(CLI::App& app);
// `previz soak` (live/soak.h).
Runner addSoakCommand(CLI::App& app);
// `previz take info | convert` (take/take.h).
Runner addTakeCommand(CLI::App& app);

}  // namespace previz::app
