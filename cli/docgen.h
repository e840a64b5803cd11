// Man page and shell completions generated from the CLI11 command tree (cli/docgen.cpp).
#pragma once
#include <string>

namespace CLI { class App; }

namespace btfc::cli {

std::string man_page(const CLI::App& app, const std::string& version);
std::string bash_completion(const CLI::App& app);
std::string zsh_completion(const CLI::App& app);

}  // namespace btfc::cli
