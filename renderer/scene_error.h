// The error a scene or settings document raises: a JSON pointer to the offending field and a message.
#pragma once

#include <stdexcept>
#include <string>

#include "proto/json_pointer.h"

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

// The documents' field pointers use the contract's one escaping of a key.
using proto::json_pointer_token;

}  // namespace tessera
