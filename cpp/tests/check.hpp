// A tiny assertion helper for the C++ tests (no test framework dependency).
//
//   CHECK(condition) << "context " << value;   // records a failure, goes on
//   int main() { return evomesh_test::run([] { ... }); }
//
// run() catches exceptions, prints a summary and returns the exit status ctest reads.
#pragma once

#include <cstdio>
#include <exception>
#include <sstream>
#include <string>

namespace evomesh_test {

inline int& failures() {
  static int count = 0;
  return count;
}
inline int& checks() {
  static int count = 0;
  return count;
}

// Collects the message of a failed check and prints it when destroyed.
class Failure {
 public:
  Failure(const char* file, int line, const char* expression) {
    out_ << file << ":" << line << ": CHECK(" << expression << ") failed";
  }
  ~Failure() {
    std::fprintf(stderr, "%s\n", out_.str().c_str());
    ++failures();
  }
  template <class T>
  Failure& operator<<(const T& value) {
    out_ << (first_ ? ": " : "") << value;
    first_ = false;
    return *this;
  }

 private:
  std::ostringstream out_;
  bool first_ = true;
};

template <class Test>
int run(Test test) {
  try {
    test();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "uncaught exception: %s\n", e.what());
    ++failures();
  }
  std::printf("%d checks, %d failures\n", checks(), failures());
  return failures() == 0 ? 0 : 1;
}

}  // namespace evomesh_test

// A one-pass loop, so the streamed context is only evaluated on failure and the
// macro is one statement (no dangling else inside an enclosing if).
#define CHECK(condition)                                                                          \
  for (bool evomesh_check_ok = (++::evomesh_test::checks(), static_cast<bool>(condition)); \
       !evomesh_check_ok; evomesh_check_ok = true)                                                 \
  ::evomesh_test::Failure(__FILE__, __LINE__, #condition)
