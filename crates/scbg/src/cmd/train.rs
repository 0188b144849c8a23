//! `scbg train predictor`.

use anyhow::Context;
use indicatif::ProgressBar;
use scbg_train::{EpochReport, Progress, TrainConfig};

use crate::cli::TrainPredictorArgs;
use crate::progress;

struct Bar(std::cell::RefCell<Option<ProgressBar>>);

impl Progress for Bar {
    fn epoch_start(&self, epoch: usize, batches: usize) {
        let pb = progress::bar(batches as u64, &format!("epoch {epoch}"));
        *self.0.borrow_mut() = Some(pb);
    }
    fn batch_done(&self, loss: f64) {
        if let Some(pb) = self.0.borrow().as_ref() {
            pb.set_message(format!("loss {loss:.3}"));
            pb.inc(1);
        }
    }
    fn epoch_end(&self, r: &EpochReport) {
        if let Some(pb) = self.0.borrow_mut().take() {
            pb.finish_and_clear();
        }
        eprintln!(
            "epoch {:>3}: train loss {:.3}  val NLL {}  val minADE@8s {}  lr {:.2e}  skipped {}  {:.1}s",
            r.epoch,
            r.train_loss,
            r.val_loss.map_or("-".into(), |v| format!("{v:.3}")),
            r.val_min_ade_8s.map_or("-".into(), |v| format!("{v:.2} m")),
            r.learning_rate,
            r.skipped_batches,
            r.seconds
        );
    }
}

pub fn load_config(path: Option<&std::path::Path>) -> anyhow::Result<TrainConfig> {
    match path {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("in {}", p.display()))
        }
        None => Ok(TrainConfig::default()),
    }
}

pub fn predictor(args: &TrainPredictorArgs) -> anyhow::Result<()> {
    let config = load_config(args.config.as_deref())?;
    let model = config.model_config()?;
    let params = {
        use burn::module::Module;
        model.init(&burn::tensor::Device::flex()).num_params()
    };
    eprintln!(
        "model: {} ({params} parameters), backend {}",
        args.config
            .as_ref()
            .map_or(config.preset.clone(), |p| p.display().to_string()),
        config.backend
    );
    let ckpt = scbg_train::train(
        &args.data,
        &args.out,
        &config,
        args.resume,
        &Bar(Default::default()),
    )?;
    eprintln!(
        "checkpoint after epoch {} in {}",
        ckpt.state.epoch,
        args.out.display()
    );
    Ok(())
}
