#pragma once
/// Ed25519 keys for alarm clears (docs/threat-model.md): each operator signs with a key of
/// their own, the gateway holds only their public keys (with names, so that who cleared is
/// proven, not claimed) and signs its answers with a key of its own. This file has the keys,
/// their files and their text form; the signed messages are in alarm_clear_auth.hpp.
///
/// Everything cryptographic is libsodium's: crypto_sign (Ed25519), crypto_kx (the tag key an
/// operator and a gateway share, from their two key pairs converted to X25519),
/// crypto_generichash (BLAKE2b: key IDs and tags), sodium_bin2base64.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace pumptherm::daemon {

/// What a secret key file holds: the 32-byte Ed25519 seed (crypto_sign_SEEDBYTES).
inline constexpr std::size_t kSeedBytes = 32;
using Seed = std::array<std::uint8_t, kSeedBytes>;
using PublicKey = std::array<std::uint8_t, 32>;
using Signature = std::array<std::uint8_t, 64>;
/// A key for keyed BLAKE2b tags (32 bytes).
using TagKey = std::array<std::uint8_t, 32>;

/// An Ed25519 key pair made from its seed. The secret half is wiped when the object goes.
class SigningKey {
 public:
  /// Throws std::invalid_argument for an all-zero seed (a file of zeros is no key), and
  /// std::runtime_error when libsodium cannot start.
  explicit SigningKey(const Seed& seed);
  /// A new key from the system's random source.
  static SigningKey Generate();
  SigningKey(const SigningKey& other);
  SigningKey& operator=(const SigningKey& other);
  ~SigningKey();

  const PublicKey& public_key() const { return public_key_; }
  const Seed& seed() const { return seed_; }
  /// KeyId(public_key()).
  std::string key_id() const;
  /// The detached signature of `bytes`.
  Signature Sign(std::span<const std::uint8_t> bytes) const;
  /// The tag key this key, as an operator's, shares with the gateway whose public key is
  /// `gateway` (crypto_kx, client side: the key the client sends with). Throws
  /// std::invalid_argument when `gateway` is not a usable Ed25519 public key.
  TagKey OperatorTagKey(const PublicKey& gateway) const;
  /// The tag key this key, as the gateway's, shares with operator key `op` (crypto_kx, server
  /// side: the key the server receives with); equal to the operator's OperatorTagKey(). Throws
  /// std::invalid_argument when `op` is not a usable Ed25519 public key.
  TagKey GatewayTagKey(const PublicKey& op) const;

 private:
  Seed seed_{};
  std::array<std::uint8_t, 64> secret_{};
  PublicKey public_key_{};
};

/// Whether `signature` is `key`'s over `bytes` (crypto_sign_verify_detached).
bool VerifySignature(const PublicKey& key, std::span<const std::uint8_t> bytes,
                     const std::uint8_t* signature);

/// Keyed BLAKE2b-256 of `bytes` (crypto_generichash with a 32-byte key).
std::array<std::uint8_t, 32> Tag(const TagKey& key, std::span<const std::uint8_t> bytes);
/// Whether `tag` is Tag(key, bytes), compared in constant time.
bool VerifyTag(const TagKey& key, std::span<const std::uint8_t> bytes, const std::uint8_t* tag);

/// A key's ID: the first 8 bytes of BLAKE2b(public key) in 16 lower-case hex digits. Names a key
/// in commands, logs and the safety state; two keys of one operator (rotation) differ in it.
std::string KeyId(const PublicKey& key);
/// "ed25519:" and the key in base64 (44 characters): the form in the configuration and .pub files.
std::string FormatPublicKey(const PublicKey& key);
/// The key of text in FormatPublicKey's form (surrounding blanks allowed); nullopt with the
/// reason in `*problem` for anything else.
std::optional<PublicKey> ParsePublicKey(std::string_view text, std::string* problem);

/// Who may own a secret key file besides the calling user: root too (the gateway's key, which
/// root writes and systemd hands to the service), or nobody else (an operator's key).
enum class KeyOwner { kCaller, kCallerOrRoot };

/// What is wrong with secret key file `path`, or "" when nothing is: it must be a regular file
/// owned by the calling user (or root, with kCallerOrRoot), that neither its group nor others
/// may read or write, in a folder that neither group nor others may write (a key in /tmp or a
/// shared folder can be swapped). Never throws.
std::string SecretKeyFileProblem(const std::string& path, KeyOwner owner);

/// Reads secret key file `path`: exactly 32 bytes, not all zero. Does not check permissions
/// (SecretKeyFileProblem). Throws std::runtime_error naming `path`.
SigningKey ReadSecretKeyFile(const std::string& path);

/// Reads public key file `path` (its first word in FormatPublicKey's form; `pumptherm keygen`
/// writes "ed25519:BASE64 NAME"). Throws std::runtime_error naming `path`.
PublicKey ReadPublicKeyFile(const std::string& path);

/// Writes a new key pair: `path` (the seed, mode 0600; an existing file is never replaced) and
/// `path`.pub ("ed25519:BASE64 NAME", mode 0644), each fsynced. Throws std::system_error naming
/// the file and what failed.
void WriteKeyFiles(const std::string& path, const SigningKey& key, const std::string& name);

/// The public key file of secret key file `path`: `path` + ".pub".
inline std::string PublicKeyPathOf(const std::string& path) { return path + ".pub"; }

}  // namespace pumptherm::daemon
