// Bearer tokens (--tokens FILE): a JSON array of {"token", "name", "role": "user" | "admin"}, re-read on SIGHUP.
// Tokens are compared in constant time (every configured token is compared, each through a fixed-size digest)
// and are never logged. Without a tokens file every caller is the anonymous admin.
#pragma once

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace tessera::server {

struct Caller {
  std::string name;  // the token's name; empty when tokens are off
  bool admin = true;
  bool authenticated = true;  // false: tokens are on and the request carried no valid one
};

class TokenSet {
 public:
  TokenSet() = default;
  // Reads the file; throws std::runtime_error naming the problem (never quoting a token).
  static TokenSet load(const std::filesystem::path& file);

  // A token as sent (after "Bearer "). Nothing when it is unknown.
  std::optional<Caller> find(const std::string& token) const;
  size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    std::string digest;  // sha256 of the token, raw bytes
    std::string name;
    bool admin = false;
  };
  std::vector<Entry> entries_;
};

class Auth {
 public:
  Auth() = default;                           // tokens off
  explicit Auth(std::filesystem::path file);  // throws like TokenSet::load

  bool enabled() const { return !file_.empty(); }
  // Re-reads the file; on error keeps the tokens it had and returns the message.
  std::string reload();
  // Who sent a request with this Authorization header value and access_token query parameter.
  Caller identify(const std::string& authorization, const std::string& access_token) const;

 private:
  std::filesystem::path file_;
  mutable std::mutex mutex_;
  std::shared_ptr<const TokenSet> tokens_ = std::make_shared<TokenSet>();
};

}  // namespace tessera::server
