// pumptherm: the project's command-line tools, one subcommand each (see `pumptherm --help`).
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <exception>

#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
std::vector<SubcommandEntry>& Subcommands() {
  static std::vector<SubcommandEntry> entries;
  return entries;
}
}  // namespace pumptherm::tools

int main(int argc, char** argv) {
  using namespace pumptherm::tools;
  CLI::App app{
      "pumptherm: tools for the pump thermal gateway (DBC, identification, thermal models)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "pumptherm " PUMPTHERM_VERSION);
  app.footer("Run `pumptherm <subcommand> --help` for the options and an example of each.");
  auto& entries = Subcommands();
  std::sort(entries.begin(), entries.end(),
            [](const auto& a, const auto& b) { return a.name < b.name; });
  std::vector<std::pair<CLI::App*, std::function<int()>>> runs;
  for (auto& e : entries) {
    CLI::App* sub = app.add_subcommand(e.name, e.description);
    runs.emplace_back(sub, e.setup(*sub));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  for (auto& [sub, run] : runs) {
    if (!sub->parsed()) continue;
    try {
      return run();
    } catch (const InputError& e) {
      fmt::print(stderr, "pumptherm {}: {}\n", sub->get_name(), e.what());
      return 2;
    } catch (const std::exception& e) {
      fmt::print(stderr, "pumptherm {}: {}\n", sub->get_name(), e.what());
      return 1;
    }
  }
  return 2;
}
