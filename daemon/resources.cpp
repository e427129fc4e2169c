#include "daemon/resources.hpp"

#include "shipped/shipped_files.hpp"

namespace pumptherm::daemon {

namespace {

shipped::FileKind ShippedKindOf(ResourceKind kind) {
  switch (kind) {
    case ResourceKind::kModel:
      return shipped::FileKind::kModel;
    case ResourceKind::kMotor:
      return shipped::FileKind::kMotor;
    case ResourceKind::kDbc:
      return shipped::FileKind::kDbc;
  }
  return shipped::FileKind::kModel;
}

}  // namespace

std::string ResolveResource(ResourceKind kind, const std::string& reference,
                            const std::string& base_dir) {
  return shipped::Resolve(ShippedKindOf(kind), reference, base_dir);
}

std::string ReadTextFile(const std::string& path) { return shipped::ReadTextFile(path); }

std::string DirectoryOf(const std::string& path) { return shipped::DirectoryOf(path); }

}  // namespace pumptherm::daemon
