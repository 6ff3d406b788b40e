// The names of an enum, written once: Names<E>::v[i] is the name of value i (the enum
// counts from 0 in this order). Parsing (parse_name, option_names.hpp), the -help text and
// error messages (names_list) and summaries (name_of) read the same table. Standard
// library only, so that pure kernel headers (rigid_body.hpp) can name their enums too.
#pragma once

#include <string>

namespace granmpm {

template <class E>
struct Names;

#define GM_NAMES(E, ...)                                                                                                                             \
  template <>                                                                                                                                        \
  struct Names<E> {                                                                                                                                  \
    static constexpr const char *v[] = {__VA_ARGS__};                                                                                                  \
    static constexpr int n = sizeof(v) / sizeof(v[0]);                                                                                               \
  };

template <class E>
const char *name_of(E e) {
  const int i = (int)e;
  return i >= 0 && i < Names<E>::n ? Names<E>::v[i] : "?";
}

// "a|b|c" (for -help and messages).
template <class E>
std::string names_list() {
  std::string s;
  for (int i = 0; i < Names<E>::n; ++i) s += std::string(i ? "|" : "") + Names<E>::v[i];
  return s;
}

} // namespace granmpm
