//! JPEG photos decoded by libjpeg-turbo's decoder with its default settings (accurate integer
//! IDCT, "fancy" upsampling): the decoder behind Pillow, OpenCV and torchvision, so a photo
//! gives the Python tools' pixels bit for bit and every parity claim downstream (style,
//! segmentation) holds for JPEG inputs. The code is mozjpeg's copy of libjpeg-turbo (its
//! decoder is libjpeg-turbo's), built from C source without SIMD so no assembler is needed.
//!
//! libjpeg reports errors by calling `error_exit`, which by default ends the process: here it
//! unwinds back to [`decode`] instead, and warnings (a truncated scan, corrupt entropy data,
//! which libjpeg fills with grey) are collected so a strict caller can refuse them.

use std::ffi::{c_int, c_void};
use std::panic::AssertUnwindSafe;

use mozjpeg_sys::{
    boolean, jpeg_common_struct, jpeg_decompress_struct, jpeg_error_mgr, JWRN_EXTRANEOUS_DATA,
    J_COLOR_SPACE,
};

/// What decoding gave: 8-bit RGB or grey pixels, or a colour space left to another decoder.
pub enum Decoded {
    Rgb {
        width: u32,
        height: u32,
        data: Vec<u8>,
    },
    Grey {
        width: u32,
        height: u32,
        data: Vec<u8>,
    },
    /// CMYK and YCCK: libjpeg does not convert them to RGB.
    Unsupported(&'static str),
}

/// Warnings libjpeg emitted while decoding, with their message codes.
#[derive(Default)]
struct Warnings(Vec<(c_int, String)>);

/// An error libjpeg raised, carried by the unwind from `error_exit` to `decode`.
struct JpegError(String);

/// libjpeg's text for the message in `err.msg_code`.
unsafe fn message(c: &mut jpeg_common_struct) -> String {
    let mut buf = [0u8; 80];
    if let Some(format) = (*c.err).format_message {
        // The binding types the buffer as shared; libjpeg writes into it (80 bytes, its
        // JMSG_LENGTH_MAX).
        format(c, &*(buf.as_mut_ptr() as *const [u8; 80]));
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    String::from_utf8_lossy(&buf[..end]).into_owned()
}

unsafe extern "C-unwind" fn error_exit(c: &mut jpeg_common_struct) {
    let m = message(c);
    // resume_unwind: no panic hook runs, nothing is printed.
    std::panic::resume_unwind(Box::new(JpegError(m)));
}

unsafe extern "C-unwind" fn emit_message(c: &mut jpeg_common_struct, level: c_int) {
    if level < 0 {
        let code = (*c.err).msg_code;
        let m = message(c);
        let w = &mut *(c.client_data as *mut Warnings);
        w.0.push((code, m));
    }
}

/// Decode `bytes`, refusing a header of more than `max_pixels` before anything is allocated.
/// With `strict`, every warning but junk bytes between markers (pixels intact) is an error.
pub fn decode(bytes: &[u8], max_pixels: u64, strict: bool) -> Result<Decoded, String> {
    let mut warnings = Warnings::default();
    // SAFETY: both structs are plain C data that libjpeg initialises; they live until the
    // decompressor is destroyed below, on success and after an unwind alike.
    let mut err: jpeg_error_mgr = unsafe { std::mem::zeroed() };
    let mut c: jpeg_decompress_struct = unsafe { std::mem::zeroed() };
    unsafe {
        mozjpeg_sys::jpeg_std_error(&mut err);
        err.error_exit = Some(error_exit);
        err.emit_message = Some(emit_message);
        c.common.err = &mut err;
        mozjpeg_sys::jpeg_create_decompress(&mut c);
        c.common.client_data = &mut warnings as *mut Warnings as *mut c_void;
    }
    let run = std::panic::catch_unwind(AssertUnwindSafe(|| unsafe {
        run(&mut c, bytes, max_pixels)
    }));
    unsafe { mozjpeg_sys::jpeg_destroy_decompress(&mut c) };
    let decoded = match run {
        Ok(r) => r?,
        Err(payload) => match payload.downcast::<JpegError>() {
            Ok(e) => return Err(format!("JPEG data: {}", e.0)),
            Err(other) => std::panic::resume_unwind(other),
        },
    };
    if strict {
        if let Some((_, m)) = warnings
            .0
            .iter()
            .find(|(code, _)| *code != JWRN_EXTRANEOUS_DATA)
        {
            return Err(format!("JPEG data: {m}"));
        }
    }
    Ok(decoded)
}

/// The decompression itself: header, size check, colour space, scanlines.
unsafe fn run(
    c: &mut jpeg_decompress_struct,
    bytes: &[u8],
    max_pixels: u64,
) -> Result<Decoded, String> {
    mozjpeg_sys::jpeg_mem_src(c, bytes.as_ptr(), bytes.len() as _);
    mozjpeg_sys::jpeg_read_header(c, true as boolean);
    let (w, h) = (c.image_width, c.image_height);
    if w as u64 * h as u64 > max_pixels {
        return Err(format!(
            "the header claims {w}x{h} pixels, more than the {max_pixels}-pixel limit"
        ));
    }
    let channels = match c.jpeg_color_space {
        J_COLOR_SPACE::JCS_CMYK => return Ok(Decoded::Unsupported("CMYK")),
        J_COLOR_SPACE::JCS_YCCK => return Ok(Decoded::Unsupported("YCCK")),
        J_COLOR_SPACE::JCS_GRAYSCALE => {
            c.out_color_space = J_COLOR_SPACE::JCS_GRAYSCALE;
            1
        }
        _ => {
            c.out_color_space = J_COLOR_SPACE::JCS_RGB;
            3
        }
    };
    mozjpeg_sys::jpeg_start_decompress(c);
    let (ow, oh) = (c.output_width as usize, c.output_height as usize);
    let stride = ow * channels;
    let mut data = vec![0u8; stride * oh];
    while (c.output_scanline as usize) < oh {
        let mut row = data.as_mut_ptr().add(c.output_scanline as usize * stride);
        if mozjpeg_sys::jpeg_read_scanlines(c, &mut row, 1) == 0 {
            return Err("JPEG data: the decoder stopped before the last row".into());
        }
    }
    mozjpeg_sys::jpeg_finish_decompress(c);
    let (width, height) = (ow as u32, oh as u32);
    Ok(if channels == 1 {
        Decoded::Grey {
            width,
            height,
            data,
        }
    } else {
        Decoded::Rgb {
            width,
            height,
            data,
        }
    })
}
