#pragma once
/// Registry of `pumptherm` subcommands. Each subcommand lives in its own source file and
/// registers itself with a static `SubcommandRegistrar`, so adding one touches no other file
/// but tools/CMakeLists.txt.
///
/// Exit codes (docs/architecture): 0 success, 1 the run failed, 2 bad input. A subcommand
/// throws `InputError` for bad input (message names file, row/line and column/key) and any
/// other exception for a failed run; `main` prints "pumptherm <sub>: <message>" on stderr.

#include <CLI/CLI.hpp>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace pumptherm::tools {

/// Bad input: exit code 2.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Configures `app` (options, footer with an example) and returns the function that runs the
/// subcommand after parsing; it returns the exit code.
using SubcommandSetup = std::function<std::function<int()>(CLI::App& app)>;

struct SubcommandEntry {
  std::string name;
  std::string description;
  SubcommandSetup setup;
};

/// All registered subcommands, in registration order.
std::vector<SubcommandEntry>& Subcommands();

struct SubcommandRegistrar {
  SubcommandRegistrar(std::string name, std::string description, SubcommandSetup setup) {
    Subcommands().push_back({std::move(name), std::move(description), std::move(setup)});
  }
};

}  // namespace pumptherm::tools
