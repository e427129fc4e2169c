#pragma once
/// Finding the files pumptherm ships (thermal models, motor descriptions, the DBC and its
/// mapping, plant scenarios), for the daemon and the tools alike: one search order.
///
/// A reference that contains '/', ends in ".toml" or ".dbc" (in any case: "issue_168.DBC"), or
/// names a file that exists is a path; a relative path is taken from `base_dir` (the directory
/// of the file that names it, "." for a command-line argument). Any other reference is the name
/// of a shipped file, with the kind's extension added when it lacks one. A bare file name
/// ("pumptherm.dbc") is tried as a path first and then as a name. Names are looked up, in this
/// order, in:
///   1. <directory of the running executable>/../share/pumptherm/<kind dir> (an installed tree,
///      wherever it was installed or unpacked);
///   2. <configured install prefix>/share/pumptherm/<kind dir> (CMAKE_INSTALL_FULL_DATADIR);
///   3. the source tree (a build tree run from anywhere).
/// The first regular file found wins.

#include <stdexcept>
#include <string>
#include <vector>

namespace pumptherm::shipped {

enum class FileKind { kModel, kMotor, kDbc, kScenario };

/// Thrown when no file is found: names the reference and every place looked at.
class FileNotFound : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Resolves `reference` of `kind` to the path of an existing regular file (search order above).
/// Throws FileNotFound listing every candidate path when none exists.
std::string Resolve(FileKind kind, const std::string& reference, const std::string& base_dir = ".");

/// The directories where shipped files of `kind` are looked for, in search order (they need not
/// exist). For listing what is shipped (e.g. `pumptherm plant --list`).
std::vector<std::string> SearchDirs(FileKind kind);

/// The whole contents of `path`. Throws std::runtime_error with the path and errno's reason.
std::string ReadTextFile(const std::string& path);

/// Directory part of `path` ("." when it has none).
std::string DirectoryOf(const std::string& path);

}  // namespace pumptherm::shipped
