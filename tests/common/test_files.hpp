#pragma once
/// Reading the project's files from tests and benchmarks (header only; needs nothing but the
/// standard library).

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pumptherm::test_files {

/// The source tree: the environment's PUMPTHERM_SOURCE_DIR (CTest sets it), else the macro of
/// that name where the target defines it (benchmarks run by hand), else "." (the working
/// directory is the source tree).
inline std::string SourceDir() {
  const char* dir = std::getenv("PUMPTHERM_SOURCE_DIR");
  if (dir && *dir) return dir;
#ifdef PUMPTHERM_SOURCE_DIR
  return PUMPTHERM_SOURCE_DIR;
#else
  return ".";
#endif
}

/// The team's shared data: PUMPTHERM_SHARED_DIR, else ../shared beside the source tree.
inline std::string SharedDir() {
  const char* dir = std::getenv("PUMPTHERM_SHARED_DIR");
  return dir && *dir ? dir : SourceDir() + "/../shared";
}

/// The whole contents of `path`, bytes unchanged. Throws std::runtime_error naming the path and
/// errno's reason when it cannot be opened or read.
inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw std::runtime_error(path + ": cannot read: " + std::strerror(errno));
  return ss.str();
}

/// The directory of the thermal models that ship (installed as share/pumptherm/models).
inline std::string ShippedModelDir() { return SourceDir() + "/estimators/models"; }

/// The directory of models kept for tests and figures only, not shipped (their data may not be
/// redistributed; docs/thermal-model.md).
inline std::string ReferenceModelDir() { return SourceDir() + "/tests/data/models"; }

/// The file of thermal model `name`: a shipped one, else a reference one.
inline std::string ModelPath(const std::string& name) {
  const std::string shipped = ShippedModelDir() + "/" + name + ".toml";
  return std::ifstream(shipped).good() ? shipped : ReferenceModelDir() + "/" + name + ".toml";
}

/// The directory part of `path` ("." when it has none): where a model's tables are read from.
inline std::string DirectoryOf(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : path.substr(0, slash);
}

/// The text of thermal model `name` (ModelPath). Throws std::runtime_error when absent.
inline std::string ReadModel(const std::string& name) { return ReadFile(ModelPath(name)); }

}  // namespace pumptherm::test_files
