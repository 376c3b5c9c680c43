#include "server/base/auth.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>

#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace tessera::server {

namespace {

std::string digest(const std::string& token) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  EVP_Digest(token.data(), token.size(), md, &n, EVP_sha256(), nullptr);
  return std::string(reinterpret_cast<const char*>(md), n);
}

}  // namespace

TokenSet TokenSet::load(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error("cannot read the tokens file " + file.string());
  std::ostringstream ss;
  ss << in.rdbuf();
  nlohmann::json doc = nlohmann::json::parse(ss.str(), nullptr, false);
  if (!doc.is_array()) throw std::runtime_error(file.string() + ": expected a JSON array of {token, name, role}");
  TokenSet set;
  for (size_t i = 0; i < doc.size(); ++i) {
    const nlohmann::json& e = doc[i];
    const std::string where = file.string() + ": entry " + std::to_string(i);
    if (!e.is_object() || !e.contains("token") || !e["token"].is_string() || !e.contains("name") ||
        !e["name"].is_string())
      throw std::runtime_error(where + " needs a string \"token\" and a string \"name\"");
    const std::string token = e["token"], name = e["name"], role = e.value("role", "user");
    if (token.size() < 16) throw std::runtime_error(where + ": a token has at least 16 characters");
    if (name.empty() || name.size() > 128) throw std::runtime_error(where + ": the name has 1 to 128 characters");
    if (role != "user" && role != "admin") throw std::runtime_error(where + ": role must be \"user\" or \"admin\"");
    set.entries_.push_back({digest(token), name, role == "admin"});
  }
  return set;
}

std::optional<Caller> TokenSet::find(const std::string& token) const {
  // Digests have one length, so CRYPTO_memcmp's time depends on neither the token nor which entry matches; every
  // entry is compared.
  const std::string d = digest(token);
  const Entry* found = nullptr;
  for (const Entry& e : entries_) {
    const bool same = CRYPTO_memcmp(d.data(), e.digest.data(), d.size()) == 0;
    if (same && !found) found = &e;
  }
  if (!found) return std::nullopt;
  return Caller{found->name, found->admin, true};
}

Auth::Auth(std::filesystem::path file) : file_(std::move(file)) {
  tokens_ = std::make_shared<const TokenSet>(TokenSet::load(file_));
}

std::string Auth::reload() {
  if (!enabled()) return "";
  try {
    auto fresh = std::make_shared<const TokenSet>(TokenSet::load(file_));
    std::lock_guard lock(mutex_);
    tokens_ = std::move(fresh);
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

Caller Auth::identify(const std::string& authorization, const std::string& access_token) const {
  if (!enabled()) return Caller{};
  std::shared_ptr<const TokenSet> tokens;
  {
    std::lock_guard lock(mutex_);
    tokens = tokens_;
  }
  std::string token = access_token;
  const std::string prefix = "Bearer ";
  if (authorization.size() > prefix.size() && authorization.compare(0, prefix.size(), prefix) == 0)
    token = authorization.substr(prefix.size());
  Caller nobody{"", false, false};
  if (token.empty() || token.size() > 4096) return nobody;
  auto found = tokens->find(token);
  return found ? *found : nobody;
}

}  // namespace tessera::server
