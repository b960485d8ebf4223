// Catching the ivol::Error a call throws, for tests that check its class and
// message.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "ivol/error.hpp"

namespace ivol::test {

// Runs `call` and returns the ivol::Error it throws (a test failure if none).
template <typename Call>
Error error_of(Call call) {
  try {
    call();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "no ivol::Error was thrown";
  return Error(ErrorClass::InvalidArgument, "");
}

inline bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace ivol::test
