// Labelled preview panels for `btfc bench --renders` (issue 21): one image per run and scene,
//
//   | title (the run: data and codec spec; PSNR and SSIM on a second line) ..... |
//   | ORIGINAL            | DECODED             | |ERROR| X5                      |
//   | reference render    | decoded render      | heat map of |decoded - original| |
//   | WHITE = 1.23        | WHITE = 1.23        | [colour bar black..white]       |
//   |                     |                     | 0               2.46E-01        |
//   |                     |                     | MAX 1.2E-02                     |
//
// The renders are shown as side_by_side (codecs/render.h) shows them: divided by the reference's
// 99.5th-percentile luminance ("white", printed under them). The error tile maps the largest
// channel difference e through the heat ramp black -> red -> yellow -> white, full scale at
// e = white / magnify; the colour bar under it is that ramp and its ends are labelled with the
// range in the renders' own linear units, with the largest error of the image below.
// Small renders (the flat sample is one pixel per texel) are enlarged by an integer factor,
// nearest neighbour, to at least 128 pixels so the labels fit; the text is drawn with a 5 x 7
// bitmap font of the printable ASCII upper case, digits and punctuation (lower case is drawn as
// upper case): no font file or font library, so the panels are the same on every machine.
#pragma once
#include <string>

#include "codecs/render.h"

namespace btfc {

struct PanelRect {
  int x = 0, y = 0, width = 0, height = 0;
};

struct PreviewPanel {
  RgbImage image;
  PanelRect tiles[3];     // original, decoded, error (enlarged renders)
  PanelRect labels[3];    // the text line above each tile
  PanelRect bar;          // the error's colour scale
  int scale = 1;          // render pixels -> panel pixels
  double white = 1;       // display scale of the renders (linear units shown as 1)
  double error_full_scale = 0;  // |error| at the bar's right end: white / magnify
  double error_max = 0;   // largest channel difference in the image
};

// `title`: one line per '\n', each cut to the panel's width.
// Errors: the two renders differ in size or are empty, magnify <= 0.
Result<PreviewPanel> preview_panel(const RgbImage& reference, const RgbImage& test, double magnify, const std::string& title);

// The heat ramp of side_by_side and the panels' error tile: t in [0, 1] -> black, red, yellow, white.
void heat_color(double t, float rgb[3]);

// The 5 x 7 font: draws `text` with its top-left corner at (x, y), each font pixel `scale` x
// `scale` image pixels, glyphs 6 font pixels apart; clipped to the image. Returns the width drawn.
int draw_text(RgbImage& img, int x, int y, const std::string& text, const float rgb[3], int scale = 1);
int text_width(const std::string& text, int scale = 1);

}  // namespace btfc
