//! Rust mirrors of WGSL uniform structs. A uniform is declared once with [`uniform!`]: a
//! `#[repr(C)]` [`bytemuck::Pod`] struct whose fields are named as in WGSL, so it is uploaded
//! with `bytemuck::bytes_of` and its layout can be checked against the shader's:
//! [`check_uniform`] compares its size and every field's name and byte offset with the WGSL
//! struct of the same name as naga lays it out (WGSL's alignment rules), on any machine, GPU
//! or not. A field added on one side only fails that check, not a render.

/// A Rust struct that mirrors a WGSL struct field for field (declared by [`uniform!`]).
pub trait Uniform: bytemuck::Pod {
    /// The struct's name in WGSL.
    const WGSL_NAME: &'static str;
    /// Each field's name and byte offset, in declaration order.
    fn layout() -> Vec<(&'static str, usize)>;
}

/// Declares a `#[repr(C)]` Pod struct mirroring the WGSL struct `$wgsl`, and its [`Uniform`]
/// layout. Fields must be plain `f32`/`u32` values, `[f32; 4]`/`[u32; 4]` vectors and arrays of
/// them, in WGSL's order, padded as WGSL pads them (the check says where not).
#[macro_export]
macro_rules! uniform {
    (
        $(#[$meta:meta])*
        pub struct $ty:ident as $wgsl:literal {
            $($(#[$field_meta:meta])* pub $field:ident: $field_ty:ty,)*
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Debug, Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $ty {
            $($(#[$field_meta])* pub $field: $field_ty,)*
        }

        impl $crate::uniform::Uniform for $ty {
            const WGSL_NAME: &'static str = $wgsl;
            fn layout() -> Vec<(&'static str, usize)> {
                vec![$((stringify!($field), std::mem::offset_of!($ty, $field))),*]
            }
        }
    };
}

/// Checks that `T` has the size, field names and field offsets of the WGSL struct
/// `T::WGSL_NAME` in the module `wgsl`, naming the first difference.
pub fn check_uniform<T: Uniform>(wgsl: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(wgsl)
        .map_err(|e| format!("the WGSL does not parse: {}", e.emit_to_string(wgsl)))?;
    let (members, span) = module
        .types
        .iter()
        .find_map(|(_, ty)| match (&ty.name, &ty.inner) {
            (Some(name), naga::TypeInner::Struct { members, span }) if name == T::WGSL_NAME => {
                Some((members, *span as usize))
            }
            _ => None,
        })
        .ok_or_else(|| format!("no struct {} in the WGSL", T::WGSL_NAME))?;
    let ours = T::layout();
    let theirs: Vec<(&str, usize)> = members
        .iter()
        .map(|m| (m.name.as_deref().unwrap_or("?"), m.offset as usize))
        .collect();
    for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        if a != b {
            return Err(format!(
                "{}: field {i} is {} at byte {} in Rust, {} at byte {} in WGSL",
                T::WGSL_NAME,
                a.0,
                a.1,
                b.0,
                b.1
            ));
        }
    }
    if ours.len() != theirs.len() {
        return Err(format!(
            "{}: {} fields in Rust, {} in WGSL",
            T::WGSL_NAME,
            ours.len(),
            theirs.len()
        ));
    }
    let size = std::mem::size_of::<T>();
    if size != span {
        return Err(format!(
            "{}: {size} bytes in Rust, {span} in WGSL",
            T::WGSL_NAME
        ));
    }
    Ok(())
}
