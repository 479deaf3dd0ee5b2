// The documentation's links (issue 48): README.md and every docs/*.md, each relative link
// ([text](path), [text](path#anchor), [text](#anchor), ![alt](path), <img src="path">) names a
// file of the source tree, and each anchor a heading of the Markdown file it points into, with
// anchors computed as GitHub computes them. Links inside fenced code blocks and code spans are
// not links; http(s) and mailto links are not checked. A finding names the file, the line and
// the link.
#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>

namespace vistream {
namespace {

namespace fs = std::filesystem;

// ---- Markdown, as far as links and headings go ----

// One UTF-8 code point of `s` at `*at` (advanced past it); malformed bytes read as themselves.
char32_t NextCodePoint(std::string_view s, size_t* at) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(*at);
  size_t n = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xE ? 3 : (c >> 3) == 0x1E ? 4 : 1;
  if (*at + n > s.size()) n = 1;
  char32_t cp = n == 1 ? c : n == 2 ? (c & 0x1F) : n == 3 ? (c & 0x0F) : (c & 0x07);
  for (size_t k = 1; k < n; ++k) {
    if ((byte(*at + k) & 0xC0) != 0x80) {  // not a continuation byte: take the lead byte alone
      n = 1;
      cp = c;
      break;
    }
    cp = (cp << 6) | (byte(*at + k) & 0x3F);
  }
  *at += n;
  return cp;
}

void AppendUtf8(char32_t cp, std::string* out) {
  if (cp < 0x80) {
    *out += static_cast<char>(cp);
  } else if (cp < 0x800) {
    *out += static_cast<char>(0xC0 | (cp >> 6));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  } else if (cp < 0x10000) {
    *out += static_cast<char>(0xE0 | (cp >> 12));
    *out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  } else {
    *out += static_cast<char>(0xF0 | (cp >> 18));
    *out += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
    *out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
    *out += static_cast<char>(0x80 | (cp & 0x3F));
  }
}

// Whether GitHub keeps a code point beyond ASCII in an anchor: letters and numbers (the scripts
// a heading here may use: Latin-1 and Latin Extended letters, Greek, Cyrillic; superscript
// digits and vulgar fractions); punctuation and symbols (dashes, ×, ², …, arrows) are dropped.
bool KeptBeyondAscii(char32_t cp) {
  if (cp == 0xAA || cp == 0xB5 || cp == 0xBA) return true;                 // ª µ º
  if (cp == 0xB2 || cp == 0xB3 || cp == 0xB9) return true;                 // ² ³ ¹
  if (cp >= 0xBC && cp <= 0xBE) return true;                               // ¼ ½ ¾
  if (cp >= 0xC0 && cp <= 0x24F) return cp != 0xD7 && cp != 0xF7;         // Latin letters, not × ÷
  if (cp >= 0x370 && cp <= 0x3FF) return cp != 0x37E && cp != 0x387;       // Greek, not ; ·
  if (cp >= 0x400 && cp <= 0x52F) return true;                             // Cyrillic
  return false;
}

char32_t Lower(char32_t cp) {
  if (cp >= 'A' && cp <= 'Z') return cp + 32;
  if (cp >= 0xC0 && cp <= 0xDE && cp != 0xD7) return cp + 32;  // Latin-1 capitals
  if (cp >= 0x391 && cp <= 0x3AB && cp != 0x3A2) return cp + 32;  // Greek capitals
  if (cp >= 0x410 && cp <= 0x42F) return cp + 32;                // Cyrillic capitals
  return cp;
}

// A heading's text as GitHub renders it, for its anchor: [text](target) and ![alt](src) give
// their text; code spans, emphasis and HTML tags give their content.
std::string RenderedText(std::string_view heading) {
  std::string out;
  for (size_t i = 0; i < heading.size(); ++i) {
    const char c = heading[i];
    if (c == ']' && i + 1 < heading.size() && heading[i + 1] == '(') {
      const size_t close = heading.find(')', i);
      if (close != std::string_view::npos) {
        i = close;
        continue;
      }
    }
    if (c == '<') {  // an HTML tag
      const size_t close = heading.find('>', i);
      if (close != std::string_view::npos) {
        i = close;
        continue;
      }
    }
    out += c;
  }
  return out;
}

// GitHub's anchor of a heading: its rendered text lowercased; characters other than letters,
// digits, spaces, hyphens and underscores removed (letters beyond ASCII, such as ε, kept);
// each space a hyphen.
std::string AnchorOf(std::string_view heading) {
  const std::string text = RenderedText(heading);
  std::string out;
  for (size_t at = 0; at < text.size();) {
    const char32_t cp = Lower(NextCodePoint(text, &at));
    if ((cp >= 'a' && cp <= 'z') || (cp >= '0' && cp <= '9') || cp == '-' || cp == '_') {
      out += static_cast<char>(cp);
    } else if (cp == ' ') {
      out += '-';
    } else if (cp >= 0x80 && KeptBeyondAscii(cp)) {
      AppendUtf8(cp, &out);
    }
  }
  return out;
}

// `markdown` with fenced code blocks, code spans and HTML comments blanked (each character a
// space, newlines kept, so that offsets and line numbers stay), for finding links and headings.
std::string WithoutCode(std::string_view markdown) {
  std::string s(markdown);
  // Fenced blocks: a line opening with ``` or ~~~ (up to 3 spaces in) to a line closing with
  // the same character, at least as many times. An unclosed fence runs to the end.
  size_t pos = 0;
  char fence_char = 0;
  size_t fence_len = 0;
  while (pos < s.size()) {
    size_t end = s.find('\n', pos);
    if (end == std::string::npos) end = s.size();
    size_t k = pos;
    while (k < end && k - pos < 3 && s[k] == ' ') ++k;
    size_t run = 0;
    if (k < end && (s[k] == '`' || s[k] == '~')) {
      while (k + run < end && s[k + run] == s[k]) ++run;
    }
    const bool is_fence = run >= 3;
    if (fence_char == 0) {
      if (is_fence) {
        fence_char = s[k];
        fence_len = run;
        for (size_t i = pos; i < end; ++i) s[i] = ' ';
      }
    } else {
      const bool closes = is_fence && s[k] == fence_char && run >= fence_len &&
                          s.find_first_not_of(" \t\r", k + run) >= end;
      for (size_t i = pos; i < end; ++i) s[i] = ' ';
      if (closes) fence_char = 0;
    }
    pos = end + 1;
  }
  // Code spans: a run of N backticks to the next run of exactly N, within the paragraph.
  for (size_t i = 0; i < s.size();) {
    if (s[i] != '`') {
      ++i;
      continue;
    }
    size_t n = 0;
    while (i + n < s.size() && s[i + n] == '`') ++n;
    size_t j = i + n;
    size_t close = std::string::npos;
    while (j < s.size()) {
      if (s[j] == '\n') {  // a blank line ends the paragraph
        const size_t next = s.find_first_not_of(" \t\r", j + 1);
        if (next == std::string::npos || s[next] == '\n') break;
      }
      if (s[j] == '`') {
        size_t m = 0;
        while (j + m < s.size() && s[j + m] == '`') ++m;
        if (m == n) {
          close = j;
          break;
        }
        j += m;
        continue;
      }
      ++j;
    }
    if (close == std::string::npos) {
      i += n;  // a literal backtick run
      continue;
    }
    for (size_t k = i; k < close + n; ++k) {
      if (s[k] != '\n') s[k] = ' ';
    }
    i = close + n;
  }
  // HTML comments.
  for (size_t i = s.find("<!--"); i != std::string::npos; i = s.find("<!--", i)) {
    const size_t end = s.find("-->", i + 4);
    const size_t stop = end == std::string::npos ? s.size() : end + 3;
    for (size_t k = i; k < stop; ++k) {
      if (s[k] != '\n') s[k] = ' ';
    }
    i = stop;
  }
  return s;
}

// The anchors of `markdown`'s ATX headings (# to ######, outside code), in order: a repeated
// anchor gets -1, -2, ... as on GitHub.
std::set<std::string> Anchors(std::string_view markdown) {
  const std::string text(markdown);
  const std::string plain = WithoutCode(markdown);
  std::set<std::string> anchors;
  std::map<std::string, int> seen;
  size_t pos = 0;
  while (pos < plain.size()) {
    size_t end = plain.find('\n', pos);
    if (end == std::string::npos) end = plain.size();
    size_t k = pos;
    while (k < end && k - pos < 3 && plain[k] == ' ') ++k;
    size_t hashes = 0;
    while (k + hashes < end && plain[k + hashes] == '#') ++hashes;
    if (hashes >= 1 && hashes <= 6 && (k + hashes == end || plain[k + hashes] == ' ')) {
      // The heading's own text (code spans included), without the closing #s.
      std::string heading = text.substr(k + hashes, end - k - hashes);
      while (!heading.empty() && (heading.back() == ' ' || heading.back() == '\r')) heading.pop_back();
      const size_t last = heading.find_last_not_of('#');
      if (last != std::string::npos && last + 1 < heading.size() && heading[last] == ' ') heading.resize(last);
      while (!heading.empty() && heading.front() == ' ') heading.erase(heading.begin());
      while (!heading.empty() && heading.back() == ' ') heading.pop_back();
      const std::string base = AnchorOf(heading);
      const int n = seen[base]++;
      anchors.insert(n == 0 ? base : base + "-" + std::to_string(n));
    }
    pos = end + 1;
  }
  return anchors;
}

struct Link {
  int line = 0;         // 1-based line of the target's start
  std::string written;  // as written: "[text](target)" shortened, or the <img> tag's src
  std::string target;   // path#anchor
};

// Every link target of `markdown` outside code: [text](target), ![alt](target) (a title after
// the target is dropped; <target> in angle brackets unwrapped) and <img src="target">.
std::vector<Link> Links(std::string_view markdown) {
  const std::string plain = WithoutCode(markdown);
  std::vector<Link> links;
  const auto line_of = [&](size_t offset) {
    int line = 1;
    for (size_t k = 0; k < offset && k < plain.size(); ++k) line += plain[k] == '\n';
    return line;
  };
  for (size_t i = plain.find("]("); i != std::string::npos; i = plain.find("](", i + 2)) {
    size_t j = i + 2;
    int depth = 0;
    while (j < plain.size() && plain[j] != '\n' && !(plain[j] == ')' && depth == 0)) {
      if (plain[j] == '(') ++depth;
      if (plain[j] == ')') --depth;
      ++j;
    }
    if (j >= plain.size() || plain[j] != ')') continue;  // not a link: no closing bracket on the line
    std::string target = plain.substr(i + 2, j - i - 2);
    while (!target.empty() && target.front() == ' ') target.erase(target.begin());
    if (!target.empty() && target.front() == '<') {
      const size_t close = target.find('>');
      target = target.substr(1, close == std::string::npos ? std::string::npos : close - 1);
    } else if (const size_t space = target.find(' '); space != std::string::npos) {
      target.resize(space);  // [text](target "title")
    }
    const size_t open = plain.rfind('[', i);
    const size_t from = open == std::string::npos || i - open > 200 ? i : open;
    links.push_back({line_of(i + 2), plain.substr(from, j + 1 - from), target});
  }
  for (size_t i = plain.find("<img"); i != std::string::npos; i = plain.find("<img", i + 4)) {
    const size_t end = plain.find('>', i);
    const std::string tag = plain.substr(i, end == std::string::npos ? std::string::npos : end + 1 - i);
    const size_t src = tag.find("src=");
    if (src == std::string::npos || src + 4 >= tag.size()) continue;
    const char quote = tag[src + 4];
    if (quote != '"' && quote != '\'') continue;
    const size_t close = tag.find(quote, src + 5);
    if (close == std::string::npos) continue;
    links.push_back({line_of(i), tag, tag.substr(src + 5, close - src - 5)});
  }
  return links;
}

// ---- the check ----

// Where the checked files and their targets come from: the source tree, or (for the test of the
// checker itself) a few files in memory. Paths are relative to the tree's root, '/'-separated.
class Tree {
 public:
  virtual ~Tree() = default;
  virtual bool Exists(const std::string& path) const = 0;
  virtual std::optional<std::string> Read(const std::string& path) const = 0;
};

class SourceTree : public Tree {
 public:
  explicit SourceTree(fs::path root) : root_(std::move(root)) {}
  bool Exists(const std::string& path) const override {
    std::error_code ec;
    return fs::exists(root_ / path, ec);
  }
  std::optional<std::string> Read(const std::string& path) const override {
    std::ifstream in(root_ / path, std::ios::binary);
    if (!in) return std::nullopt;
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }

 private:
  fs::path root_;
};

class MemoryTree : public Tree {
 public:
  explicit MemoryTree(std::map<std::string, std::string> files) : files_(std::move(files)) {}
  bool Exists(const std::string& path) const override {
    if (files_.contains(path)) return true;
    for (const auto& [name, text] : files_) {  // a folder: the prefix of a file's path
      if (name.starts_with(path + "/")) return true;
    }
    return false;
  }
  std::optional<std::string> Read(const std::string& path) const override {
    const auto it = files_.find(path);
    if (it == files_.end()) return std::nullopt;
    return it->second;
  }

 private:
  std::map<std::string, std::string> files_;
};

struct Finding {
  std::string file;
  int line = 0;
  std::string link;
  std::string problem;
};

std::ostream& operator<<(std::ostream& out, const Finding& f) {
  return out << f.file << ":" << f.line << ": " << f.link << ": " << f.problem;
}

bool IsExternal(const std::string& target) {
  return target.starts_with("http://") || target.starts_with("https://") || target.starts_with("mailto:");
}

// The findings of `file` (its path in `tree`, whose text is `text`): every relative link whose
// file does not exist, or whose anchor no heading of its Markdown file has.
std::vector<Finding> CheckLinks(const std::string& file, const std::string& text, const Tree& tree) {
  std::vector<Finding> findings;
  std::map<std::string, std::set<std::string>> anchors_of;
  const auto anchors = [&](const std::string& path, const std::string& markdown) -> const std::set<std::string>& {
    auto it = anchors_of.find(path);
    if (it == anchors_of.end()) it = anchors_of.emplace(path, Anchors(markdown)).first;
    return it->second;
  };
  for (const Link& link : Links(text)) {
    if (IsExternal(link.target)) continue;
    if (link.target.empty()) {
      findings.push_back({file, link.line, link.written, "an empty link"});
      continue;
    }
    const size_t hash = link.target.find('#');
    const std::string path_part = link.target.substr(0, hash);
    const std::string anchor = hash == std::string::npos ? "" : link.target.substr(hash + 1);
    std::string target_file = file;
    if (!path_part.empty()) {
      const fs::path resolved = (fs::path(file).parent_path() / path_part).lexically_normal();
      target_file = resolved.generic_string();
      while (target_file.size() > 1 && target_file.back() == '/') target_file.pop_back();
      if (target_file.starts_with("..") || resolved.is_absolute()) {
        findings.push_back({file, link.line, link.written, "points outside the repository (" + target_file + ")"});
        continue;
      }
      if (!tree.Exists(target_file)) {
        findings.push_back({file, link.line, link.written, "no such file: " + target_file});
        continue;
      }
    }
    if (hash == std::string::npos || !target_file.ends_with(".md")) continue;
    const std::optional<std::string> markdown = target_file == file ? std::optional<std::string>(text)
                                                                      : tree.Read(target_file);
    if (!markdown) {
      findings.push_back({file, link.line, link.written, "cannot read " + target_file});
      continue;
    }
    if (!anchors(target_file, *markdown).contains(anchor)) {
      findings.push_back({file, link.line, link.written, "no heading of " + target_file + " has the anchor #" + anchor});
    }
  }
  return findings;
}

// README.md and docs/*.md, relative to the source tree's root.
std::vector<std::string> DocumentationFiles() {
  std::vector<std::string> files = {"README.md"};
  std::set<std::string> docs;
  for (const fs::directory_entry& e : fs::directory_iterator(fs::path(VISTREAM_SOURCE_DIR) / "docs")) {
    if (e.path().extension() == ".md") docs.insert("docs/" + e.path().filename().string());
  }
  files.insert(files.end(), docs.begin(), docs.end());
  return files;
}

// ---- the tests ----

TEST(Docs, AnchorsAreComputedAsGitHubComputesThem) {
  EXPECT_EQ(AnchorOf("The two commands"), "the-two-commands");
  EXPECT_EQ(AnchorOf("ε-masks on the move"), "ε-masks-on-the-move");
  EXPECT_EQ(AnchorOf("Small neighbourhoods: the ε-superset"), "small-neighbourhoods-the-ε-superset");
  EXPECT_EQ(AnchorOf("Levels of detail: what accuracy costs (issue 45)"), "levels-of-detail-what-accuracy-costs-issue-45");
  EXPECT_EQ(AnchorOf("The client's overlay"), "the-clients-overlay");
  EXPECT_EQ(AnchorOf("Start, stop, reload"), "start-stop-reload");
  EXPECT_EQ(AnchorOf("1. OpenStreetMap"), "1-openstreetmap");
  EXPECT_EQ(AnchorOf("`vistream scene walks` and --json"), "vistream-scene-walks-and---json");
  EXPECT_EQ(AnchorOf("Tables 1 and 2 — on city1 × 2"), "tables-1-and-2--on-city1--2");
  EXPECT_EQ(AnchorOf("Ε upper and snake_case"), "ε-upper-and-snake_case");
  EXPECT_EQ(AnchorOf("A [link](x.md) in it"), "a-link-in-it");
  // Repeats get -1, -2; headings in code are none.
  const std::set<std::string> anchors = Anchors("# Tests\n\n## Tests\n\n```sh\n# Tests\n```\n### Tests ###\n");
  EXPECT_EQ(anchors, (std::set<std::string>{"tests", "tests-1", "tests-2"}));
}

TEST(Docs, TheCheckerFindsABrokenLinkAndABrokenAnchor) {
  const MemoryTree tree({
      {"README.md", ""},
      {"docs/a.md", "# A page\n\n## Real heading\n"},
      {"bench/figures/x.png", ""},
  });
  const std::string page =
      "# Here\n"
      "[fine](a.md#real-heading), [fine too](#here), ![a picture](../bench/figures/x.png),\n"
      "<img src=\"../bench/figures/x.png\" alt=\"fine\">, [web](https://example.org/#x), [a\n"
      "folder](../bench/figures)\n"
      "[gone](missing.md) and [wrong anchor](a.md#no-such-heading)\n"
      "```sh\n[in a fence](nothing.md)\n```\n"
      "`[in code](nothing.md)`\n";
  const std::vector<Finding> findings = CheckLinks("docs/b.md", page, tree);
  ASSERT_EQ(findings.size(), 2u) << ::testing::PrintToString(findings);
  EXPECT_EQ(findings[0].file, "docs/b.md");
  EXPECT_EQ(findings[0].line, 5);
  EXPECT_NE(findings[0].link.find("missing.md"), std::string::npos) << findings[0];
  EXPECT_NE(findings[0].problem.find("no such file: docs/missing.md"), std::string::npos) << findings[0];
  EXPECT_EQ(findings[1].line, 5);
  EXPECT_NE(findings[1].problem.find("#no-such-heading"), std::string::npos) << findings[1];
}

TEST(Docs, EveryPageTheIssueNamesExists) {
  const std::vector<std::string> files = DocumentationFiles();
  for (const char* page : {"README.md", "docs/README.md", "docs/deploying.md", "docs/scaling-out.md",
                           "docs/your-own-city.md", "docs/client.md", "docs/browser.md", "docs/server.md",
                           "docs/tool.md", "docs/simulator.md", "docs/scenes.md", "docs/visibility.md",
                           "docs/development.md", "docs/benchmarks.md"}) {
    EXPECT_NE(std::find(files.begin(), files.end(), page), files.end()) << page;
  }
}

TEST(Docs, EveryRelativeLinkAndAnchorResolves) {
  const SourceTree tree(VISTREAM_SOURCE_DIR);
  size_t links = 0;
  for (const std::string& file : DocumentationFiles()) {
    const std::optional<std::string> text = tree.Read(file);
    ASSERT_TRUE(text.has_value()) << file;
    links += Links(*text).size();
    for (const Finding& f : CheckLinks(file, *text, tree)) ADD_FAILURE() << f;
  }
  EXPECT_GT(links, 100u);  // the checker saw the links at all
}

}  // namespace
}  // namespace vistream
