// "Did you mean": the known name closest to a misspelt one, for the messages of the daemon, the renderer and the
// command line (an unknown property, enum value, material name, option or command). Header-only, so that every
// program can use it without linking anything.
//
// Closeness is the optimal string alignment distance (Levenshtein distance with transpositions of adjacent
// characters: Damerau 1964, "A technique for computer detection and correction of spelling errors"), compared case
// insensitively. A name is suggested when it is at most a third of the longer name's length away (at least 1), so
// "albdo" suggests "albedo" and "spp_" suggests "spp", but "x" suggests nothing.
#pragma once

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::proto {

// Edits (insertions, deletions, substitutions, adjacent transpositions) between a and b, ignoring case.
inline size_t edit_distance(std::string_view a, std::string_view b) {
  auto lower = [](char c) { return static_cast<char>(std::tolower(static_cast<unsigned char>(c))); };
  const size_t n = a.size(), m = b.size();
  // Three rows of the (n+1) x (m+1) table: the two previous ones (for transpositions) and the current one.
  std::vector<size_t> before(m + 1), previous(m + 1), current(m + 1);
  for (size_t j = 0; j <= m; ++j) previous[j] = j;
  for (size_t i = 1; i <= n; ++i) {
    current[0] = i;
    for (size_t j = 1; j <= m; ++j) {
      const size_t cost = lower(a[i - 1]) == lower(b[j - 1]) ? 0 : 1;
      current[j] = std::min({previous[j] + 1, current[j - 1] + 1, previous[j - 1] + cost});
      if (i > 1 && j > 1 && lower(a[i - 1]) == lower(b[j - 2]) && lower(a[i - 2]) == lower(b[j - 1]))
        current[j] = std::min(current[j], before[j - 2] + 1);
    }
    std::swap(before, previous);
    std::swap(previous, current);
  }
  return previous[m];
}

// The candidate closest to `name` within the threshold above (the first of equally close ones), or "" when none is.
// Names longer than 64 characters are not compared (a hostile document's keys cost no quadratic time).
template <typename Names>
std::string closest_name(std::string_view name, const Names& candidates) {
  constexpr size_t kLongest = 64;
  std::string best;
  if (name.empty() || name.size() > kLongest) return best;
  size_t best_distance = 0;
  for (const auto& c : candidates) {
    const std::string_view candidate(c);
    if (candidate.empty() || candidate.size() > kLongest || candidate == name) continue;
    const size_t limit = std::max<size_t>(1, std::max(name.size(), candidate.size()) / 3);
    const size_t d = edit_distance(name, candidate);
    if (d <= limit && (best.empty() || d < best_distance)) {
      best = std::string(candidate);
      best_distance = d;
    }
  }
  return best;
}

// " (did you mean \"NAME\"?)" for the closest candidate, or "" when none is close: appended to a message that
// names what was not known.
template <typename Names>
std::string did_you_mean(std::string_view name, const Names& candidates) {
  const std::string best = closest_name(name, candidates);
  return best.empty() ? std::string() : " (did you mean \"" + best + "\"?)";
}

inline std::string did_you_mean(std::string_view name, std::initializer_list<std::string_view> candidates) {
  return did_you_mean<std::initializer_list<std::string_view>>(name, candidates);
}

}  // namespace tessera::proto
