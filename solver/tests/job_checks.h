// Test helper for the jobs' validity tests.
#pragma once

#include <string>

#include "mocapedit/errors.h"

// The reason Validate() rejects a job (InvalidInput's message), or "" when it accepts it.
template <typename Job>
std::string Rejection(const Job& job) {
  try {
    job.Validate();
    return "";
  } catch (const mocapedit::InvalidInput& e) {
    return e.what();
  }
}
