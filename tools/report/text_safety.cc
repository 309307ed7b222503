#include "report/text_safety.h"

namespace lpoe {
namespace tools {

std::string ValidUtf8(const std::string& text) {
  static const char kReplacement[] = "\xEF\xBF\xBD";
  std::string out;
  out.reserve(text.size());
  const auto* p = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  size_t i = 0;
  while (i < n) {
    const unsigned char c = p[i];
    if (c < 0x80) {
      out.push_back(static_cast<char>(c));
      ++i;
      continue;
    }
    // The sequence's length and the range of its second byte (Unicode table 3-7).
    int len = 0;
    unsigned char lo = 0x80, hi = 0xBF;
    if (c >= 0xC2 && c <= 0xDF) {
      len = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
      len = 3;
      if (c == 0xE0) lo = 0xA0;
      if (c == 0xED) hi = 0x9F;  // no surrogates
    } else if (c >= 0xF0 && c <= 0xF4) {
      len = 4;
      if (c == 0xF0) lo = 0x90;
      if (c == 0xF4) hi = 0x8F;  // at most U+10FFFF
    }
    if (len == 0) {  // a continuation byte or an invalid lead byte
      out += kReplacement;
      ++i;
      continue;
    }
    size_t k = 1;
    for (; k < static_cast<size_t>(len) && i + k < n; ++k) {
      const unsigned char b = p[i + k];
      const bool ok = k == 1 ? (b >= lo && b <= hi) : (b >= 0x80 && b <= 0xBF);
      if (!ok) break;
    }
    if (k == static_cast<size_t>(len)) {
      out.append(text, i, k);
    } else {
      out += kReplacement;  // the maximal invalid subpart: the bytes read so far
    }
    i += k;
  }
  return out;
}

std::string TruncateUtf8(const std::string& text, size_t max_bytes) {
  if (text.size() <= max_bytes) return text;
  size_t cut = max_bytes;
  // Back up over continuation bytes to the start of the character that does not fit.
  while (cut > 0 && (static_cast<unsigned char>(text[cut]) & 0xC0) == 0x80) --cut;
  return text.substr(0, cut) + "...";
}

std::string CommentText(const std::string& text) {
  std::string out = ValidUtf8(text);
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return out;
}

// A label as PLplot may take it: valid UTF-8, truncated, and PLplot's escape character '#' doubled
// (so that a name holding "#u" or "#[0x25c6]" is drawn as written, not interpreted).
std::string PlotLabel(const std::string& text) {
  const std::string cut = TruncateUtf8(ValidUtf8(text), kMaxPlotLabelBytes);
  std::string out;
  for (char c : cut) {
    if (c == '#') out += '#';
    out += c;
  }
  return out;
}

}  // namespace tools
}  // namespace lpoe
