// The error a scene or settings document raises: a JSON pointer to the offending field and a message.
#pragma once

#include <stdexcept>
#include <string>

namespace tessera {

class SceneError : public std::runtime_error {
 public:
  SceneError(std::string pointer, const std::string& message)
      : std::runtime_error(message), pointer_(std::move(pointer)) {}
  const std::string& pointer() const { return pointer_; }

 private:
  std::string pointer_;
};

// A scene load given up because its stop token was asked to stop (a daemon shutting down, a job cancelled or paused):
// no fault of the document.
class LoadStopped : public std::runtime_error {
 public:
  LoadStopped() : std::runtime_error("the scene load was stopped") {}
};

// RFC 6901 escaping of one reference token.
inline std::string json_pointer_token(const std::string& key) {
  std::string out;
  for (char c : key) {
    if (c == '~')
      out += "~0";
    else if (c == '/')
      out += "~1";
    else
      out += c;
  }
  return out;
}

}  // namespace tessera
