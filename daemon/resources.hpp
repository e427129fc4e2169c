#pragma once
/// Finding the files pumptherm ships (thermal models, motor descriptions, the DBC and its
/// mapping) by name, for the daemon and the tools alike.
///
/// A reference that contains '/' or ends in ".toml"/".dbc" is a path (relative paths are taken
/// from `base_dir`, the directory of the file that names them). Otherwise it is the name of a
/// shipped file, looked up in <exe>/../share/pumptherm/<kind> (an installed tree), then in the
/// configured install directory, then in the source tree (a build tree).

#include <stdexcept>
#include <string>

namespace pumptherm::daemon {

enum class ResourceKind { kModel, kMotor, kDbc };

/// Resolves `reference` of `kind` to an existing file path. Throws std::runtime_error naming
/// the reference and every place looked at when nothing is found.
std::string ResolveResource(ResourceKind kind, const std::string& reference,
                            const std::string& base_dir = ".");

/// The whole contents of `path`. Throws std::runtime_error with the path and errno's reason.
std::string ReadTextFile(const std::string& path);

/// Directory part of `path` ("." when it has none).
std::string DirectoryOf(const std::string& path);

}  // namespace pumptherm::daemon
