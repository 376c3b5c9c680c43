#include "server/base/problem.h"

namespace tessera::server {

namespace {
struct Kind {
  int status;
  const char* slug;
  const char* title;
};
constexpr Kind kKinds[] = {
    {400, "bad-request", "Bad request"},
    {401, "unauthorized", "Unauthorized"},
    {403, "forbidden", "Forbidden"},
    {404, "not-found", "Not found"},
    {405, "method-not-allowed", "Method not allowed"},
    {408, "request-timeout", "Request timeout"},
    {409, "conflict", "Conflict with the job's state"},
    {413, "payload-too-large", "Request body too large"},
    {414, "uri-too-long", "Request URI too long"},
    {415, "unsupported-media-type", "Unsupported media type"},
    {422, "invalid-document", "Invalid document"},
    {429, "too-many-requests", "Too many requests"},
    {431, "header-fields-too-large", "Request header fields too large"},
    {500, "internal-error", "Internal server error"},
    {501, "not-implemented", "Not implemented"},
    {503, "unavailable", "Service unavailable"},
    {507, "insufficient-storage", "Insufficient storage"},
};
const Kind& kind_of(int status) {
  for (const Kind& k : kKinds)
    if (k.status == status) return k;
  return kind_of(status < 500 ? 400 : 500);
}

// What a problem quotes of a request is cut to this many bytes: a document with a 50 MB key must not be answered
// with it (twice: in the detail and in the pointer).
constexpr size_t kMaxQuotedBytes = 1024;

std::string capped(const std::string& text) {
  if (text.size() <= kMaxQuotedBytes) return text;
  size_t cut = kMaxQuotedBytes;
  while (cut > 0 && (static_cast<unsigned char>(text[cut]) & 0xC0) == 0x80) --cut;  // not inside a UTF-8 character
  return text.substr(0, cut) + "… (" + std::to_string(text.size() - cut) + " more bytes)";
}
}  // namespace

std::string Problem::type() const {
  return std::string("https://tessera.dev/problems/") + kind_of(status).slug;
}
std::string Problem::title() const {
  return kind_of(status).title;
}

nlohmann::json Problem::to_json() const {
  nlohmann::json j = {{"type", type()}, {"title", title()}, {"status", status}, {"detail", capped(detail)}};
  if (pointer) j["pointer"] = capped(*pointer);
  if (errors.size() > 1) {
    j["errors"] = nlohmann::json::array();
    for (const auto& [at, what] : errors) j["errors"].push_back({{"pointer", capped(at)}, {"detail", capped(what)}});
  }
  if (pending) j["pending"] = *pending;
  return j;
}

Problem insufficient_storage(const std::string& why, const std::string& kept) {
  return Problem{507, why + "; " + kept + ". Retry once finished jobs or assets have been deleted", std::nullopt};
}

Problem stopping_problem() {
  return Problem{503, "the daemon is shutting down; nothing was stored. Retry shortly", std::nullopt, 5};
}

}  // namespace tessera::server
