#include "daemon/clear_keys.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

#include "daemon/state_store.hpp"
#include "daemon/unique_fd.hpp"

namespace pumptherm::daemon {
namespace {

static_assert(kSeedBytes == crypto_sign_SEEDBYTES);
static_assert(sizeof(PublicKey) == crypto_sign_PUBLICKEYBYTES);
static_assert(sizeof(Signature) == crypto_sign_BYTES);
static_assert(crypto_kx_SESSIONKEYBYTES == 32 && crypto_kx_PUBLICKEYBYTES == 32);

constexpr std::string_view kPublicKeyPrefix = "ed25519:";

void StartSodiumForKeys() {
  // libsodium asks for sodium_init() before any other call; it is idempotent and thread-safe.
  static const int init = sodium_init();
  if (init < 0) throw std::runtime_error("libsodium cannot start (sodium_init)");
}

/// An X25519 key pair from an Ed25519 secret key, for crypto_kx.
struct KxPair {
  std::array<std::uint8_t, 32> pk{}, sk{};
  ~KxPair() { sodium_memzero(sk.data(), sk.size()); }
};

KxPair KxOf(const std::array<std::uint8_t, 64>& ed_secret, const PublicKey& ed_public) {
  KxPair p;
  if (crypto_sign_ed25519_sk_to_curve25519(p.sk.data(), ed_secret.data()) != 0 ||
      crypto_sign_ed25519_pk_to_curve25519(p.pk.data(), ed_public.data()) != 0) {
    throw std::invalid_argument("this key cannot be converted to X25519");
  }
  return p;
}

std::array<std::uint8_t, 32> KxPublicOf(const PublicKey& ed_public) {
  std::array<std::uint8_t, 32> out{};
  if (crypto_sign_ed25519_pk_to_curve25519(out.data(), ed_public.data()) != 0)
    throw std::invalid_argument("not a usable Ed25519 public key");
  return out;
}

std::string KeyFileModeText(mode_t mode) { return fmt::format("{:04o}", mode & 07777); }

std::string DirectoryOfPath(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  return slash == 0 ? "/" : path.substr(0, slash);
}

/// Writes `contents` to a new file `path` (O_EXCL) with mode `mode`, fsynced.
void WriteNewFile(const std::string& path, std::string_view contents, mode_t mode) {
  UniqueFd fd(::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode));
  if (!fd.valid()) throw std::system_error(errno, std::generic_category(), "create " + path);
  if (::fchmod(fd.get(), mode) != 0)  // whatever the umask
    throw std::system_error(errno, std::generic_category(), "chmod " + path);
  std::size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd.get(), contents.data() + done, contents.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw std::system_error(errno, std::generic_category(), "write " + path);
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd.get()) != 0)
    throw std::system_error(errno, std::generic_category(), "fsync " + path);
}

}  // namespace

SigningKey::SigningKey(const Seed& seed) : seed_(seed) {
  StartSodiumForKeys();
  if (std::all_of(seed.begin(), seed.end(), [](std::uint8_t b) { return b == 0; }))
    throw std::invalid_argument("the key is all zero bytes: not a key");
  crypto_sign_seed_keypair(public_key_.data(), secret_.data(), seed_.data());
}

SigningKey SigningKey::Generate() {
  StartSodiumForKeys();
  Seed seed{};
  randombytes_buf(seed.data(), seed.size());
  SigningKey key(seed);
  sodium_memzero(seed.data(), seed.size());
  return key;
}

SigningKey::SigningKey(const SigningKey& other) = default;
SigningKey& SigningKey::operator=(const SigningKey& other) = default;

SigningKey::~SigningKey() {
  sodium_memzero(seed_.data(), seed_.size());
  sodium_memzero(secret_.data(), secret_.size());
}

std::string SigningKey::key_id() const { return KeyId(public_key_); }

Signature SigningKey::Sign(std::span<const std::uint8_t> bytes) const {
  Signature sig{};
  crypto_sign_detached(sig.data(), nullptr, bytes.data(), bytes.size(), secret_.data());
  return sig;
}

TagKey SigningKey::OperatorTagKey(const PublicKey& gateway) const {
  const KxPair me = KxOf(secret_, public_key_);
  const auto server = KxPublicOf(gateway);
  TagKey rx{}, tx{};
  if (crypto_kx_client_session_keys(rx.data(), tx.data(), me.pk.data(), me.sk.data(),
                                    server.data()) != 0) {
    throw std::invalid_argument("the gateway's public key is not usable");
  }
  sodium_memzero(rx.data(), rx.size());
  return tx;
}

TagKey SigningKey::GatewayTagKey(const PublicKey& op) const {
  const KxPair me = KxOf(secret_, public_key_);
  const auto client = KxPublicOf(op);
  TagKey rx{}, tx{};
  if (crypto_kx_server_session_keys(rx.data(), tx.data(), me.pk.data(), me.sk.data(),
                                    client.data()) != 0) {
    throw std::invalid_argument("the operator's public key is not usable");
  }
  sodium_memzero(tx.data(), tx.size());
  return rx;
}

bool VerifySignature(const PublicKey& key, std::span<const std::uint8_t> bytes,
                     const std::uint8_t* signature) {
  StartSodiumForKeys();
  return crypto_sign_verify_detached(signature, bytes.data(), bytes.size(), key.data()) == 0;
}

std::array<std::uint8_t, 32> Tag(const TagKey& key, std::span<const std::uint8_t> bytes) {
  StartSodiumForKeys();
  std::array<std::uint8_t, 32> out{};
  crypto_generichash(out.data(), out.size(), bytes.data(), bytes.size(), key.data(), key.size());
  return out;
}

bool VerifyTag(const TagKey& key, std::span<const std::uint8_t> bytes, const std::uint8_t* tag) {
  const auto want = Tag(key, bytes);
  return sodium_memcmp(want.data(), tag, want.size()) == 0;
}

std::string KeyId(const PublicKey& key) {
  StartSodiumForKeys();
  std::array<std::uint8_t, 16> h{};
  crypto_generichash(h.data(), h.size(), key.data(), key.size(), nullptr, 0);
  std::string out;
  for (std::size_t i = 0; i < 8; ++i) out += fmt::format("{:02x}", h[i]);
  return out;
}

std::string FormatPublicKey(const PublicKey& key) {
  StartSodiumForKeys();
  constexpr int kVariant = sodium_base64_VARIANT_ORIGINAL;
  std::string b64(sodium_base64_ENCODED_LEN(32, kVariant), '\0');
  sodium_bin2base64(b64.data(), b64.size(), key.data(), key.size(), kVariant);
  b64.resize(std::strlen(b64.c_str()));
  return std::string(kPublicKeyPrefix) + b64;
}

std::optional<PublicKey> ParsePublicKey(std::string_view text, std::string* problem) {
  StartSodiumForKeys();
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t' || text.back() == '\n'))
    text.remove_suffix(1);
  if (text.substr(0, kPublicKeyPrefix.size()) != kPublicKeyPrefix) {
    *problem = "a public key reads \"ed25519:\" and 44 base64 characters (pumptherm keygen)";
    return std::nullopt;
  }
  text.remove_prefix(kPublicKeyPrefix.size());
  PublicKey key{};
  std::size_t len = 0;
  const std::string b64(text);
  if (sodium_base642bin(key.data(), key.size(), b64.c_str(), b64.size(), nullptr, &len, nullptr,
                        sodium_base64_VARIANT_ORIGINAL) != 0 ||
      len != key.size()) {
    *problem = "the base64 after \"ed25519:\" is not 32 bytes";
    return std::nullopt;
  }
  std::array<std::uint8_t, 32> x{};
  if (crypto_sign_ed25519_pk_to_curve25519(x.data(), key.data()) != 0) {
    *problem = "not a usable Ed25519 public key";
    return std::nullopt;
  }
  return key;
}

std::string SecretKeyFileProblem(const std::string& path, KeyOwner owner) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return fmt::format("cannot stat {}: {}", path, std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return fmt::format("{} is not a regular file", path);
  const uid_t me = ::geteuid();
  const bool root_ok = owner == KeyOwner::kCallerOrRoot;
  if (st.st_uid != me && !(root_ok && st.st_uid == 0)) {
    return fmt::format("{} belongs to uid {}, not to {} (uid {}): a key is its owner's alone", path,
                       st.st_uid, root_ok ? "root or this user" : "you", me);
  }
  if ((st.st_mode & (S_IRWXG | S_IRWXO)) != 0) {
    return fmt::format("{} is open to its group or others (mode {}): make it 0600 (chmod 0600 {})",
                       path, KeyFileModeText(st.st_mode), path);
  }
  const std::string dir = DirectoryOfPath(path);
  struct stat ds {};
  if (::stat(dir.c_str(), &ds) != 0)
    return fmt::format("cannot stat {}: {}", dir, std::strerror(errno));
  if ((ds.st_mode & (S_IWGRP | S_IWOTH)) != 0) {
    return fmt::format(
        "{} is in {}, which others may write (mode {}): they could swap the key; keep it in a "
        "folder only its owner writes",
        path, dir, KeyFileModeText(ds.st_mode));
  }
  if (ds.st_uid != me && ds.st_uid != 0) {
    return fmt::format(
        "{} is in {}, which belongs to uid {}: keep it in a folder of your own or "
        "root's",
        path, dir, ds.st_uid);
  }
  return "";
}

SigningKey ReadSecretKeyFile(const std::string& path) {
  std::optional<std::string> text;
  try {
    text = ReadFileIfExists(path);
  } catch (const std::system_error& e) {
    throw std::runtime_error(e.what());
  }
  if (!text) throw std::runtime_error(fmt::format("cannot open {}: it does not exist", path));
  if (text->size() != kSeedBytes) {
    const std::size_t n = text->size();
    sodium_memzero(text->data(), text->size());
    throw std::runtime_error(
        fmt::format("{} holds {} bytes; a secret key is {} bytes (pumptherm keygen FILE makes one)",
                    path, n, kSeedBytes));
  }
  Seed seed{};
  std::memcpy(seed.data(), text->data(), seed.size());
  sodium_memzero(text->data(), text->size());
  try {
    SigningKey key(seed);
    sodium_memzero(seed.data(), seed.size());
    return key;
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(fmt::format("{}: {}", path, e.what()));
  }
}

PublicKey ReadPublicKeyFile(const std::string& path) {
  std::optional<std::string> text;
  try {
    text = ReadFileIfExists(path);
  } catch (const std::system_error& e) {
    throw std::runtime_error(e.what());
  }
  if (!text) throw std::runtime_error(fmt::format("cannot open {}: it does not exist", path));
  const std::string_view t(*text);
  const std::size_t end = t.find_first_of(" \t\n");
  std::string problem;
  const auto key = ParsePublicKey(t.substr(0, end), &problem);
  if (!key) throw std::runtime_error(fmt::format("{}: {}", path, problem));
  return *key;
}

void WriteKeyFiles(const std::string& path, const SigningKey& key, const std::string& name) {
  const std::string pub = PublicKeyPathOf(path);
  struct stat st {};
  if (::stat(pub.c_str(), &st) == 0)
    throw std::system_error(EEXIST, std::generic_category(), "create " + pub);
  WriteNewFile(path, std::string_view(reinterpret_cast<const char*>(key.seed().data()), kSeedBytes),
               0600);
  WriteNewFile(pub, FormatPublicKey(key.public_key()) + (name.empty() ? "" : " " + name) + "\n",
               0644);
  const std::string dir = DirectoryOfPath(path);
  UniqueFd d(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!d.valid() || ::fsync(d.get()) != 0)
    throw std::system_error(errno, std::generic_category(), "fsync " + dir);
}

}  // namespace pumptherm::daemon
