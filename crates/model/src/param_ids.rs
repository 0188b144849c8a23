//! Parameter ids derived from the parameters' paths, so that a saved model is the same bytes
//! in every process.
//!
//! burn gives each parameter a random id when it is created, and writes the ids into the
//! weights file and keys the optimizer state by them. Two runs of the same training, which
//! reach the same weights, would otherwise write different files. [`with_path_ids`] replaces
//! every id with a hash of the model's name and the parameter's path (`history.step_mlp.
//! layers.0.weight`): unique within a model, different between models, the same everywhere.

use burn::module::{Module, ModuleMapper, Param, ParamId};
use burn::tensor::{Bool, Int, Tensor};

/// `module` with every parameter's id derived from `model` and its path.
pub fn with_path_ids<M: Module>(module: M, model: &str) -> M {
    module.map(&mut PathIds {
        model: model.to_owned(),
        path: Vec::new(),
    })
}

struct PathIds {
    model: String,
    path: Vec<String>,
}

impl PathIds {
    /// FNV-1a over the model's name and the path, finished with the SplitMix64 mixer.
    fn id(&self) -> ParamId {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for part in std::iter::once(&self.model).chain(&self.path) {
            for b in part.bytes().chain([b'.']) {
                h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
            }
        }
        ParamId::from(scbg_base::seed::mix(h, 0))
    }

    fn set<T: burn::module::ParameterValue>(&self, mut param: Param<T>) -> Param<T> {
        param.id = self.id();
        param
    }
}

impl ModuleMapper for PathIds {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_owned());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        self.set(param)
    }

    fn map_int<const D: usize>(&mut self, param: Param<Tensor<D, Int>>) -> Param<Tensor<D, Int>> {
        self.set(param)
    }

    fn map_bool<const D: usize>(
        &mut self,
        param: Param<Tensor<D, Bool>>,
    ) -> Param<Tensor<D, Bool>> {
        self.set(param)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::ModuleVisitor;

    struct Ids(Vec<ParamId>);
    impl ModuleVisitor for Ids {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push(param.id);
        }
    }

    fn ids<M: Module>(m: &M) -> Vec<ParamId> {
        let mut v = Ids(Vec::new());
        m.visit(&mut v);
        v.0
    }

    #[test]
    fn ids_are_unique_repeatable_and_named_by_model() {
        let device = crate::device::device("flex").unwrap();
        let config = crate::Preset::CpuSmall.config();
        let a = ids(&with_path_ids(config.init(&device), "multipath"));
        let b = ids(&with_path_ids(config.init(&device), "multipath"));
        assert_eq!(a, b);
        let mut unique = a.clone();
        unique.sort_by_key(|id| id.val());
        unique.dedup();
        assert_eq!(unique.len(), a.len(), "ids collide");
        let c = ids(&with_path_ids(config.init(&device), "other"));
        assert!(a.iter().zip(&c).all(|(x, y)| x != y));
    }
}
