// pumptherm keygen: makes an Ed25519 key pair for signed alarm clears (docs/threat-model.md):
// an operator's own key (clear-trip signs with it; the gateway lists its public half in
// alarms.clear_operators) or the gateway's (gateway.signing_key_file; it signs its answers).
#include <fmt/core.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <system_error>

#include "daemon/clear_keys.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

struct KeygenOptions {
  std::string file;
  std::string name;
  bool make_dir = false;
};

/// The folder of `path`, made (mode 0700) when asked and missing.
void MakeFolder(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos || slash == 0) return;
  const std::string dir = path.substr(0, slash);
  struct stat st {};
  if (::stat(dir.c_str(), &st) == 0) return;
  MakeFolder(dir);
  if (::mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST)
    throw std::system_error(errno, std::generic_category(), "mkdir " + dir);
}

int RunKeygen(const KeygenOptions& o) {
  if (o.name.empty()) throw InputError("--name: who holds the key (an operator, or the gateway)");
  if (o.make_dir) MakeFolder(o.file);
  const daemon::SigningKey key = daemon::SigningKey::Generate();
  try {
    daemon::WriteKeyFiles(o.file, key, o.name);
  } catch (const std::system_error& e) {
    if (e.code().value() == EEXIST)
      throw InputError(
          fmt::format("{}: a key is there already; keygen never replaces one", e.what()));
    throw;
  }
  // The secret half must pass the checks clear-trip and the daemon make (folder, owner, mode).
  const std::string problem = daemon::SecretKeyFileProblem(o.file, daemon::KeyOwner::kCallerOrRoot);
  const std::string pub = daemon::FormatPublicKey(key.public_key());
  fmt::print(
      "wrote {} (secret, mode 0600) and {} (public)\n"
      "key ID {}\n"
      "For an operator's key: list it in the gateway's configuration,\n"
      "  [[alarms.clear_operators]]\n"
      "  name = \"{}\"\n"
      "  public_key = \"{}\"\n"
      "For the gateway's key: set gateway.signing_key_file = \"{}\", and give {} to the\n"
      "operators' hosts (pumptherm clear-trip --gateway-key).\n",
      o.file, daemon::PublicKeyPathOf(o.file), key.key_id(), o.name, pub, o.file,
      daemon::PublicKeyPathOf(o.file));
  if (!problem.empty()) {
    fmt::print(stderr, "warning: {}\n", problem);
    return 1;
  }
  return 0;
}

const SubcommandRegistrar kKeygenRegistrar{
    "keygen", "Make an Ed25519 key pair for signed alarm clears (an operator's or the gateway's)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<KeygenOptions>();
      app.add_option("file", o->file, "The secret key file to write (FILE.pub gets the public key)")
          ->required();
      app.add_option("--name", o->name, "Who holds the key: an operator's name, or the gateway's")
          ->required();
      app.add_flag("--make-dir", o->make_dir, "Make the file's folder (mode 0700) when missing");
      app.footer(
          "Exit codes: 0 written, 1 written but its folder or owner would be refused, 2 bad input "
          "(an existing key is never replaced).\n"
          "Examples:\n"
          "  pumptherm keygen ~/.config/pumptherm/operator.key --name alice --make-dir\n"
          "  sudo pumptherm keygen /etc/pumptherm/gateway.key --name gateway-hall2");
      return [o] { return RunKeygen(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
