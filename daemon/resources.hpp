#pragma once
/// The daemon's names for finding shipped files (thermal models, motor descriptions, the DBC and
/// its mapping): the search order is pumptherm::shipped's (shipped/shipped_files.hpp), shared
/// with the tools.

#include <stdexcept>
#include <string>

namespace pumptherm::daemon {

enum class ResourceKind { kModel, kMotor, kDbc };

/// Resolves `reference` of `kind` to an existing file path (shipped::Resolve). Throws
/// std::runtime_error naming the reference and every place looked at when nothing is found.
std::string ResolveResource(ResourceKind kind, const std::string& reference,
                            const std::string& base_dir = ".");

/// The whole contents of `path`. Throws std::runtime_error with the path and errno's reason.
std::string ReadTextFile(const std::string& path);

/// Directory part of `path` ("." when it has none).
std::string DirectoryOf(const std::string& path);

}  // namespace pumptherm::daemon
