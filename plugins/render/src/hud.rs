//! On-screen text (the viewer's and videos' heads-up display): a built-in 5 x 7 bitmap font
//! drawn into RGB or RGBA images on the CPU, white on a translucent dark box.
//!
//! Letters are drawn as capitals; characters without a glyph are drawn as `?`.

/// Glyph width, px (at scale 1).
pub const GLYPH_W: u32 = 5;
/// Glyph height, px (at scale 1).
pub const GLYPH_H: u32 = 7;
/// Horizontal advance of one character, px (at scale 1).
const ADVANCE: u32 = GLYPH_W + 1;
/// Line height, px (at scale 1).
const LINE_H: u32 = GLYPH_H + 3;
/// Padding of the text box, px (at scale 1).
const PAD: u32 = 2;

/// Rows of a glyph, top first; bit 4 is the leftmost column.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        ' ' => [0; 7],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        '|' => [0x04; 7],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '!' => [0x04, 0x04, 0x04, 0x04, 0x04, 0, 0x04],
        '#' => [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A],
        '*' => [0, 0x04, 0x15, 0x0E, 0x15, 0x04, 0],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0, 0x04],
    }
}

/// Size `(width, height)` in px of the text box [`draw_text`] draws for `lines` at `scale`.
pub fn text_box_size(lines: &[String], scale: u32) -> (u32, u32) {
    let cols = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0) as u32;
    if cols == 0 {
        return (0, 0);
    }
    (
        (cols * ADVANCE - 1 + 2 * PAD) * scale,
        (lines.len() as u32 * LINE_H - (LINE_H - GLYPH_H) + 2 * PAD) * scale,
    )
}

/// Draws `lines` of text into a row-major image of `width x height` pixels with `channels`
/// (3: RGB, 4: RGBA) bytes each, in a box whose top-left corner is at `(x, y)`: the box darkens
/// what is under it (RGBA images get alpha 0.6 there, 1 on the glyphs), glyphs are `color`, each
/// glyph pixel `scale x scale` pixels. Whatever falls outside the image is clipped.
#[allow(clippy::too_many_arguments)]
pub fn draw_text(
    image: &mut [u8],
    width: u32,
    height: u32,
    channels: usize,
    (x, y): (u32, u32),
    scale: u32,
    lines: &[String],
    color: [u8; 3],
) {
    let scale = scale.max(1);
    let (bw, bh) = text_box_size(lines, scale);
    if channels < 3 || image.len() < (width * height) as usize * channels {
        return;
    }
    let mut put = |px: u32, py: u32, glyph: bool| {
        if px >= width || py >= height {
            return;
        }
        let i = (py * width + px) as usize * channels;
        let p = &mut image[i..i + channels];
        if glyph {
            p[..3].copy_from_slice(&color);
        } else {
            for c in &mut p[..3] {
                *c = (u16::from(*c) * 2 / 5) as u8;
            }
        }
        if channels == 4 {
            p[3] = if glyph { 255 } else { p[3].max(153) };
        }
    };
    for py in y..y + bh {
        for px in x..x + bw {
            put(px, py, false);
        }
    }
    for (row, line) in lines.iter().enumerate() {
        let top = y + (PAD + row as u32 * LINE_H) * scale;
        for (col, ch) in line.chars().enumerate() {
            let left = x + (PAD + col as u32 * ADVANCE) * scale;
            for (gy, bits) in glyph(ch).iter().enumerate() {
                for gx in 0..GLYPH_W {
                    if bits & (0x10 >> gx) == 0 {
                        continue;
                    }
                    for sy in 0..scale {
                        for sx in 0..scale {
                            put(left + gx * scale + sx, top + gy as u32 * scale + sy, true);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lit(img: &[u8], w: u32, x: u32, y: u32) -> bool {
        let i = ((y * w + x) * 3) as usize;
        img[i..i + 3] == [255, 255, 255]
    }

    #[test]
    fn a_glyph_lands_where_its_bits_say() {
        let (w, h) = (20u32, 16u32);
        let mut img = vec![100u8; (w * h * 3) as usize];
        draw_text(&mut img, w, h, 3, (0, 0), 1, &["1".into()], [255; 3]);
        // '1': top row 0x04 -> only column 2 lit, at (PAD + 2, PAD).
        for gx in 0..GLYPH_W {
            assert_eq!(lit(&img, w, PAD + gx, PAD), gx == 2, "column {gx}");
        }
        // bottom row 0x0E -> columns 1..=3
        for gx in 0..GLYPH_W {
            assert_eq!(lit(&img, w, PAD + gx, PAD + 6), (1..=3).contains(&gx));
        }
        // the box darkens (100 * 2 / 5 = 40), outside it stays
        assert_eq!(img[0], 40);
        let (bw, bh) = text_box_size(&["1".into()], 1);
        assert_eq!((bw, bh), (5 + 2 * PAD, 7 + 2 * PAD));
        let outside = ((bh * w + bw) * 3) as usize;
        assert_eq!(img[outside], 100);
    }

    #[test]
    fn scale_doubles_the_box_and_clips_at_the_border() {
        let lines = vec!["reward 0.25".to_string(), "success true".to_string()];
        let (w1, h1) = text_box_size(&lines, 1);
        assert_eq!(text_box_size(&lines, 2), (2 * w1, 2 * h1));
        // An image smaller than the box: no panic, every pixel inside the box is touched.
        let mut img = vec![200u8; 10 * 6 * 4];
        draw_text(&mut img, 10, 6, 4, (3, 2), 2, &lines, [255, 0, 0]);
        assert!(img.chunks(4).skip(2 * 10 + 3).take(7).all(|p| p[3] >= 153));
        // Different text, different pixels.
        let mut a = vec![0u8; 80 * 12 * 3];
        let mut b = a.clone();
        draw_text(&mut a, 80, 12, 3, (0, 0), 1, &["step 1".into()], [255; 3]);
        draw_text(&mut b, 80, 12, 3, (0, 0), 1, &["step 7".into()], [255; 3]);
        assert_ne!(a, b);
    }

    #[test]
    fn lowercase_draws_as_capitals_and_unknowns_as_question_marks() {
        assert_eq!(glyph('a'), glyph('A'));
        assert_eq!(glyph('~'), glyph('?'));
    }
}
