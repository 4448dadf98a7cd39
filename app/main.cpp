// previz — one CLI, one subcommand per stage. Errors from the libraries are previz::Error and
// end here: one line a person can act on, exit code 1 (2 for bad command-line usage).
#include <iostream>
#include <map>

#include "app/commands.h"
#include "core/error.h"

int main(int argc, char** argv) {
  CLI::App app{"previz — depth-aware green-screen previz for virtual-production studios"};
  app.set_version_flag("--version", std::string("previz ") + PREVIZ_VERSION);
  app.require_subcommand(0, 1);
  app.fallthrough(false);

  std::map<CLI::App*, previz::app::Runner> runners;
  auto add = [&](const char* name, previz::app::Runner (*fn)(CLI::App&)) {
    previz::app::Runner runner = fn(app);
    runners[app.get_subcommand(name)] = std::move(runner);
  };
  add("synth", previz::app::addSynthCommand);
  add("take", previz::app::addTakeCommand);
  add("camera", previz::app::addCameraCommand);
  add("calib", previz::app::addCalibCommand);
  add("carve", previz::app::addCarveCommand);
  add("batch", previz::app::addBatchCommand);
  add("rig", previz::app::addRigCommand);
  add("track", previz::app::addTrackCommand);
  add("composite", previz::app::addCompositeCommand);
  add("run", previz::app::addRunCommand);
  add("tracker", previz::app::addTrackerCommand);
  add("bench", previz::app::addBenchCommand);
  add("soak", previz::app::addSoakCommand);
  add("demo", previz::app::addDemoCommand);
  CLI::App* help = app.add_subcommand("help", "Show the commands (or `previz <cmd> --help`)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  if (app.get_subcommands().empty() || help->parsed()) {
    std::cout << app.get_formatter()->make_help(&app, app.get_name(), CLI::AppFormatMode::Normal);
    return app.get_subcommands().empty() ? 2 : 0;
  }
  try {
    for (CLI::App* sub : app.get_subcommands()) {
      auto it = runners.find(sub);
      if (it != runners.end()) return it->second();
    }
  } catch (const previz::Error& e) {
    std::cerr << "previz: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "previz: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
