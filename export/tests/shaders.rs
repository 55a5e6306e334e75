//! `nelf export shaders`: our WGSL passes translated by naga to GLSL 4.50 and HLSL.
//! Every GLSL file must compile with Khronos' reference front end,
//! `glslangValidator` (Debian `glslang-tools`, installed by `scripts/test`): a missing
//! validator fails the test. No HLSL compiler installs here (DXC and FXC are not
//! Debian packages); the HLSL is checked for its entry points and registers only.

use std::path::Path;
use std::process::Command;

use nelf_export::shaders::{ENGINE_PASSES, write_engine_shaders};

fn glslang(file: &Path) -> std::process::Output {
    match Command::new("glslangValidator").arg(file).output() {
        Ok(out) => out,
        Err(e) => panic!(
            "glslangValidator cannot run ({e}): install it with `apt-get install glslang-tools` (scripts/test does)"
        ),
    }
}

#[test]
fn every_pass_translates_and_its_glsl_compiles() {
    let dir = tempfile::tempdir().unwrap();
    let report = write_engine_shaders(dir.path()).unwrap();
    assert_eq!(report.passes.len(), ENGINE_PASSES.len());
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("shaders.json")).unwrap()).unwrap();
    assert_eq!(manifest["passes"].as_array().unwrap().len(), ENGINE_PASSES.len());
    let mut glsl_files = 0;
    for pass in &report.passes {
        assert!(!pass.entries.is_empty(), "{} has no entry point", pass.pass);
        assert!(!pass.bindings.is_empty(), "{} has no resources", pass.pass);
        let wgsl = std::fs::read_to_string(dir.path().join(&pass.wgsl_file)).unwrap();
        assert!(
            !wgsl.lines().any(|l| l.trim_start().starts_with("#import")),
            "{}: imports resolved",
            pass.pass
        );
        let hlsl = std::fs::read_to_string(dir.path().join(&pass.hlsl_file)).unwrap();
        for b in &pass.bindings {
            if b.hlsl_class == "s" {
                // naga's HLSL puts samplers in a heap, indexed per bind group.
                let index = format!("nagaGroup{}SamplerIndexArray", b.group);
                assert!(
                    hlsl.contains("nagaSamplerHeap") && hlsl.contains(&index),
                    "{}: {index}",
                    pass.pass
                );
                continue;
            }
            // naga writes `register(<class><n>)`, adding `, space<g>` when g > 0.
            let tail = if b.hlsl_space == 0 {
                format!(" : register({}{})", b.hlsl_class, b.hlsl_register)
            } else {
                format!(
                    " : register({}{}, space{})",
                    b.hlsl_class, b.hlsl_register, b.hlsl_space
                )
            };
            assert!(
                // (naga may suffix a name that clashes with another, `indirection_1`).
                hlsl.lines()
                    .any(|l| l.contains(&format!(" {}", b.name)) && l.contains(&tail)),
                "{}: HLSL register of {} (…{tail}) in:\n{}",
                pass.pass,
                b.name,
                hlsl.lines()
                    .filter(|l| l.contains("register("))
                    .collect::<Vec<_>>()
                    .join("\n")
            );
        }
        for entry in &pass.entries {
            assert!(
                hlsl.contains(&entry.hlsl_name),
                "{}: HLSL entry {}",
                pass.pass,
                entry.hlsl_name
            );
            let file = dir.path().join(&entry.glsl_file);
            let glsl = std::fs::read_to_string(&file).unwrap();
            assert!(glsl.starts_with("#version 450 core"), "{}", entry.glsl_file);
            let out = glslang(&file);
            assert!(
                out.status.success(),
                "glslangValidator rejects {}:\n{}{}",
                entry.glsl_file,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            glsl_files += 1;
        }
    }
    // relight: shade + fill; march: march; display: vertex + fragment.
    assert!(glsl_files >= 5, "{glsl_files} GLSL files");
}

/// The translation is a pure function of the WGSL: twice gives the same files.
#[test]
fn translation_is_deterministic() {
    let (_, a) = nelf_export::shaders::engine_shaders().unwrap();
    let (_, b) = nelf_export::shaders::engine_shaders().unwrap();
    assert_eq!(a, b);
}
