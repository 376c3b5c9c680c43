#include "server/problem.h"

namespace tessera::server {

namespace {
struct Kind {
  int status;
  const char* slug;
  const char* title;
};
constexpr Kind kKinds[] = {
    {400, "bad-request", "Bad request"},
    {404, "not-found", "Not found"},
    {405, "method-not-allowed", "Method not allowed"},
    {409, "conflict", "Conflict with the job's state"},
    {413, "payload-too-large", "Request body too large"},
    {414, "uri-too-long", "Request URI too long"},
    {415, "unsupported-media-type", "Unsupported media type"},
    {422, "invalid-document", "Invalid document"},
    {500, "internal-error", "Internal server error"},
    {503, "unavailable", "Service unavailable"},
    {507, "insufficient-storage", "Insufficient storage"},
};
const Kind& kind_of(int status) {
  for (const Kind& k : kKinds)
    if (k.status == status) return k;
  return status < 500 ? kKinds[0] : kKinds[8];
}
}  // namespace

std::string Problem::type() const {
  return std::string("https://tessera.dev/problems/") + kind_of(status).slug;
}
std::string Problem::title() const {
  return kind_of(status).title;
}

nlohmann::json Problem::to_json() const {
  nlohmann::json j = {{"type", type()}, {"title", title()}, {"status", status}, {"detail", detail}};
  if (pointer) j["pointer"] = *pointer;
  return j;
}

Problem insufficient_storage(const std::string& why, const std::string& kept) {
  return Problem{507, why + "; " + kept + ". Retry once finished jobs or assets have been deleted", std::nullopt};
}

}  // namespace tessera::server
