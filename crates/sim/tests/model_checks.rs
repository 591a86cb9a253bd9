//! A surrogate is used only on the parameter set it was trained on: a half-scale model
//! filed under `full_size/` (or given by path) is refused naming both sets.

use sim::episode::{target_model, ModelKind};
use sim::Scenario;
use std::path::{Path, PathBuf};

fn models_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

fn scenario(params: &str) -> Scenario {
    let text = format!(
        r#"{{"id":"m","category":"straight_urban","params":"{params}","prior":"test","seed":1,
        "road":{{"lanes":3,"lane_width":3.5,"shoulder":1.0,"length":800.0,"entry":0.0,"transition":0.0}},
        "mu":0.9,"adhesion":"high","obstacles":[],
        "target":{{"s":100.0,"d":3.5,"heading":0.0,"vx":5.0,"vy":0.0,"r":0.0}},
        "bullet":{{"s":95.0,"d":0.0,"heading":0.0,"vx":6.0,"vy":0.0,"r":0.0}},
        "driver":{{"kind":"lane_keep","offset":3.5,"gain":1.0}},"t_max":10.0,"eps_psi":0.349066}}"#
    )
    .replace('\n', " ");
    Scenario::from_json_line(&text, 1).expect("valid scenario")
}

fn load(kind: ModelKind, dir: &Path, path: Option<&Path>, sc: &Scenario) -> Result<(), String> {
    let params = sc.params.load().unwrap();
    target_model(kind, dir, path, sc, &params, 0.05)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn a_model_of_another_parameter_set_is_refused() {
    let full = scenario("full_size");
    let half = scenario("half_scale");
    for kind in [ModelKind::Pinn, ModelKind::PicoPinn] {
        // The shipped files are where they belong.
        load(kind, &models_dir(), None, &full).unwrap();
        load(kind, &models_dir(), None, &half).unwrap();
        // A half-scale file under full_size/.
        let dir = std::env::temp_dir().join(format!("picopit-model-checks-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("full_size")).unwrap();
        let name = format!("{}.safetensors", kind.name());
        std::fs::copy(
            models_dir().join("half_scale").join(&name),
            dir.join("full_size").join(&name),
        )
        .unwrap();
        let e = load(kind, &dir, None, &full).unwrap_err();
        assert!(
            e.contains("param_set = \"half_scale\"") && e.contains("full_size parameter set"),
            "{e}"
        );
        // The same given by path.
        let path = models_dir().join("half_scale").join(&name);
        let e = load(kind, &models_dir(), Some(&path), &full).unwrap_err();
        assert!(e.contains("half_scale"), "{e}");
    }
}
