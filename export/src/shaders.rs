//! Engine shaders: the viewer's relight, march, display, view and reflect passes
//! translated from our WGSL (the same `#import`-resolved source the viewer compiles,
//! `nelf_render::wgsl`) to GLSL 4.50 (one file per entry point, as GLSL has one
//! `main`) and HLSL (Shader Model 5.1, one file per pass) by naga's back ends, never
//! by hand, so an engine port starts from exactly what our viewer runs.
//!
//! Written by [`write_engine_shaders`]:
//!
//! * `wgsl/<pass>.wgsl`: the preprocessed source;
//! * `glsl/<pass>.<entry>.<comp|vert|frag>`: GLSL 4.50 core, explicit bindings;
//! * `hlsl/<pass>.hlsl`: every entry point of the pass;
//! * `shaders.json`: per pass and entry point its stage, workgroup size, the GLSL
//!   file and HLSL function name, and each resource's WGSL `@group/@binding`, its
//!   GLSL `binding` and its HLSL `register(…, space…)`.
//!
//! Override constants take their WGSL defaults.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use naga::back::{glsl, hlsl};
use naga::valid::{Capabilities, ValidationFlags, Validator};
use nelf_format::io_error::IoResultExt;
use nelf_render::wgsl::{DISPLAY_WGSL, MARCH_WGSL, REFLECT_WGSL, RELIGHT_WGSL, VIEW_WGSL, preprocess};
use serde::Serialize;

use crate::ExportError;

/// The passes an engine needs: (file stem, WGSL text). `view` only for a view-dependent
/// asset (format 1.2) and `reflect` only for a reflection asset (format 1.3): per voxel
/// toward the eye, after the relight, before the march.
pub const ENGINE_PASSES: &[(&str, &str)] = &[
    ("relight", RELIGHT_WGSL),
    ("march", MARCH_WGSL),
    ("display", DISPLAY_WGSL),
    ("view", VIEW_WGSL),
    ("reflect", REFLECT_WGSL),
];

/// One translated entry point.
#[derive(Debug, Clone, Serialize)]
pub struct EntryReport {
    /// Its WGSL name.
    pub name: String,
    /// `compute`, `vertex` or `fragment`.
    pub stage: String,
    /// Compute workgroup size (`[1, 1, 1]` for other stages).
    pub workgroup_size: [u32; 3],
    /// The GLSL file, relative to the output folder.
    pub glsl_file: String,
    /// The entry point's name in the HLSL file.
    pub hlsl_name: String,
}

/// One resource (buffer, texture, sampler) of a pass.
#[derive(Debug, Clone, Serialize)]
pub struct BindingReport {
    /// The WGSL variable name.
    pub name: String,
    /// WGSL `@group`.
    pub group: u32,
    /// WGSL `@binding`.
    pub binding: u32,
    /// The GLSL `layout(binding = …)`.
    pub glsl_binding: u8,
    /// HLSL register class: `b` constant buffer, `t` read-only buffer or texture,
    /// `u` read-write buffer or storage texture, `s` sampler (naga's HLSL reads
    /// samplers from a heap, `nagaSamplerHeap` at `s0`, through the index buffer
    /// `nagaGroup<g>SamplerIndexArray` at `t<g>, space255`: an engine fills entry
    /// `register` of that buffer with the sampler's heap index).
    pub hlsl_class: String,
    /// HLSL register number.
    pub hlsl_register: u32,
    /// HLSL register space (`space…`; naga omits it when 0).
    pub hlsl_space: u32,
}

/// One pass's translation.
#[derive(Debug, Clone, Serialize)]
pub struct PassReport {
    /// The pass (`relight`, `march`, `display`).
    pub pass: String,
    /// The preprocessed WGSL file, relative to the output folder.
    pub wgsl_file: String,
    /// The HLSL file, relative to the output folder.
    pub hlsl_file: String,
    /// Its entry points.
    pub entries: Vec<EntryReport>,
    /// Its resources.
    pub bindings: Vec<BindingReport>,
}

/// What [`write_engine_shaders`] wrote (also saved as `shaders.json`).
#[derive(Debug, Clone, Serialize)]
pub struct ShaderReport {
    /// GLSL version written.
    pub glsl_version: String,
    /// HLSL shader model written.
    pub hlsl_shader_model: String,
    /// The translator.
    pub translator: String,
    /// Every pass.
    pub passes: Vec<PassReport>,
}

impl ShaderReport {
    /// The lines `nelf export shaders` prints for shaders written to `dir`.
    #[must_use]
    pub fn to_text(&self, dir: &Path) -> String {
        use std::fmt::Write as _;
        let mut text = String::new();
        for pass in &self.passes {
            let entries: Vec<String> = pass
                .entries
                .iter()
                .map(|e| format!("{} ({})", e.name, e.stage))
                .collect();
            let _ = writeln!(text, "{}: {}", pass.pass, entries.join(", "));
        }
        let _ = writeln!(
            text,
            "GLSL {} and HLSL SM {} written to {} (bindings: {})",
            self.glsl_version,
            self.hlsl_shader_model,
            dir.display(),
            dir.join("shaders.json").display()
        );
        text
    }
}

fn shader_error(pass: &str, what: &str, message: impl std::fmt::Display) -> ExportError {
    ExportError::Shader(format!("{pass}: {what}: {message}"))
}

fn stage_name(stage: naga::ShaderStage) -> (&'static str, &'static str) {
    match stage {
        naga::ShaderStage::Vertex => ("vertex", "vert"),
        naga::ShaderStage::Fragment => ("fragment", "frag"),
        _ => ("compute", "comp"),
    }
}

/// The HLSL register class of a resource.
fn hlsl_class(module: &naga::Module, var: &naga::GlobalVariable) -> &'static str {
    match var.space {
        naga::AddressSpace::Uniform => "b",
        naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => "u",
        naga::AddressSpace::Handle => match module.types[var.ty].inner {
            naga::TypeInner::Sampler { .. } => "s",
            naga::TypeInner::Image {
                class: naga::ImageClass::Storage { .. },
                ..
            } => "u",
            _ => "t",
        },
        _ => "t",
    }
}

/// Translates one pass: (report, files as (relative path, text)).
fn translate_pass(pass: &str, wgsl: &str) -> Result<(PassReport, Vec<(PathBuf, String)>), ExportError> {
    let source = preprocess(&format!("{pass}.wgsl"), wgsl).map_err(|e| shader_error(pass, "imports", e))?;
    let module = naga::front::wgsl::parse_str(&source)
        .map_err(|e| shader_error(pass, "WGSL", e.emit_to_string(&source)))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::default())
        .validate(&module)
        .map_err(|e| shader_error(pass, "validation", e.emit_to_string(&source)))?;
    // Pipeline-overridable constants take their WGSL defaults (the viewer's
    // `COUNT_SAMPLES` diagnostic is off); GLSL and HLSL have no overrides.
    let (module, info) = naga::back::pipeline_constants::process_overrides(
        &module,
        &info,
        None,
        &naga::back::PipelineConstants::default(),
    )
    .map_err(|e| shader_error(pass, "override constants", e))?;
    let (module, info) = (module.into_owned(), info.into_owned());

    // One flat GLSL binding per resource, in (group, binding) order.
    let mut resources: Vec<(naga::ResourceBinding, String, &'static str)> = module
        .global_variables
        .iter()
        .filter_map(|(_, var)| {
            let class = hlsl_class(&module, var);
            var.binding
                .map(|b| (b, var.name.clone().unwrap_or_default(), class))
        })
        .collect();
    resources.sort_by_key(|(b, _, _)| (b.group, b.binding));
    let mut glsl_map = glsl::BindingMap::default();
    let mut bindings = Vec::new();
    for (index, (binding, name, class)) in resources.iter().enumerate() {
        let flat =
            u8::try_from(index).map_err(|_| shader_error(pass, "bindings", "more than 255 resources"))?;
        glsl_map.insert(*binding, flat);
        bindings.push(BindingReport {
            name: name.clone(),
            group: binding.group,
            binding: binding.binding,
            glsl_binding: flat,
            hlsl_class: (*class).into(),
            hlsl_register: binding.binding,
            hlsl_space: binding.group,
        });
    }

    let mut files = vec![(PathBuf::from(format!("wgsl/{pass}.wgsl")), source.clone())];
    let glsl_options = glsl::Options {
        version: glsl::Version::Desktop(450),
        writer_flags: glsl::WriterFlags::empty(),
        binding_map: glsl_map,
        zero_initialize_workgroup_memory: true,
    };
    let mut entries = Vec::new();
    for entry in &module.entry_points {
        let (stage, extension) = stage_name(entry.stage);
        let pipeline = glsl::PipelineOptions {
            shader_stage: entry.stage,
            entry_point: entry.name.clone(),
            multiview: None,
        };
        let mut text = String::new();
        glsl::Writer::new(
            &mut text,
            &module,
            &info,
            &glsl_options,
            &pipeline,
            naga::proc::BoundsCheckPolicies::default(),
        )
        .and_then(|mut w| w.write())
        .map_err(|e| shader_error(pass, &format!("GLSL of {}", entry.name), e))?;
        let glsl_file = format!("glsl/{pass}.{}.{extension}", entry.name);
        files.push((PathBuf::from(&glsl_file), text));
        entries.push(EntryReport {
            name: entry.name.clone(),
            stage: stage.into(),
            workgroup_size: entry.workgroup_size,
            glsl_file,
            hlsl_name: String::new(),
        });
    }

    // HLSL: naga's default places @group(g) @binding(b) at register b, space g.
    let hlsl_options = hlsl::Options {
        shader_model: hlsl::ShaderModel::V5_1,
        ..hlsl::Options::default()
    };
    let pipeline = hlsl::PipelineOptions::default();
    let mut text = String::new();
    let reflection = hlsl::Writer::new(&mut text, &hlsl_options, &pipeline)
        .write(&module, &info, None)
        .map_err(|e| shader_error(pass, "HLSL", e))?;
    for (entry, name) in entries.iter_mut().zip(reflection.entry_point_names) {
        entry.hlsl_name = name.map_err(|e| shader_error(pass, &format!("HLSL of {}", entry.name), e))?;
    }
    let hlsl_file = format!("hlsl/{pass}.hlsl");
    files.push((PathBuf::from(&hlsl_file), text));
    Ok((
        PassReport {
            pass: pass.into(),
            wgsl_file: format!("wgsl/{pass}.wgsl"),
            hlsl_file,
            entries,
            bindings,
        },
        files,
    ))
}

/// Translates every pass and returns the report with the files (relative path,
/// text), without writing anything.
pub fn engine_shaders() -> Result<(ShaderReport, Vec<(PathBuf, String)>), ExportError> {
    let mut passes = Vec::new();
    let mut files = Vec::new();
    for (pass, wgsl) in ENGINE_PASSES {
        let (report, pass_files) = translate_pass(pass, wgsl)?;
        passes.push(report);
        files.extend(pass_files);
    }
    let report = ShaderReport {
        glsl_version: "450 core".into(),
        hlsl_shader_model: "5.1".into(),
        translator: "naga 30 (wgsl-in, glsl-out, hlsl-out)".into(),
        passes,
    };
    let json = serde_json::to_string_pretty(&report).map_err(|e| ExportError::Shader(e.to_string()))? + "\n";
    files.push((PathBuf::from("shaders.json"), json));
    Ok((report, files))
}

/// Writes the engine shaders into `dir` (created if needed), each file atomically.
pub fn write_engine_shaders(dir: &Path) -> Result<ShaderReport, ExportError> {
    let (report, files) = engine_shaders()?;
    let mut made = BTreeSet::new();
    for (relative, text) in &files {
        let path = dir.join(relative);
        if let Some(parent) = path.parent()
            && made.insert(parent.to_path_buf())
        {
            std::fs::create_dir_all(parent).with_path(parent)?;
        }
        nelf_format::atomic::write_bytes_atomically(&path, text.as_bytes()).with_path(&path)?;
    }
    Ok(report)
}
