"""training.runner.stop_on_ctrl_c_callback: a Ctrl-C during SB3's learn stops it at the next env step, even when the
SIGINT is handled inside a finalizer, where a KeyboardInterrupt would be ignored by Python and training went on."""
import os
import signal

import pytest

pytest.importorskip("stable_baselines3", reason="the callback is an SB3 callback")
pytest.importorskip("torch", reason="SB3 needs torch")


def _learn_with_a_sigint_inside_a_finalizer(callbacks, at_step=20, total=4096):
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    class SendsSigintFromAFinalizer:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            sum(i for i in range(1000))  # (Python runs the handler here, inside the finalizer)

    class AtStep(BaseCallback):
        def _on_step(self):
            if self.n_calls == at_step:
                SendsSigintFromAFinalizer()  # (collected at once: its __del__ runs here)
            return True

    model = PPO("MlpPolicy", gym.make("CartPole-v1"), n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=total, callback=[AtStep(), *callbacks])
    return model


def test_a_ctrl_c_inside_a_finalizer_stops_training_at_the_next_step_and_the_handler_is_restored(python_sigint_handler):
    from training.runner import stop_on_ctrl_c_callback
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    ctrl_c = stop_on_ctrl_c_callback()
    model = _learn_with_a_sigint_inside_a_finalizer([ctrl_c])
    assert ctrl_c.requested and model.num_timesteps < 4096
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_without_it_the_same_ctrl_c_is_lost(python_sigint_handler):
    # the case the callback exists for: Python ignores ("Exception ignored in ...") the KeyboardInterrupt raised in
    # the finalizer, and learn runs to its end
    model = _learn_with_a_sigint_inside_a_finalizer([])
    assert model.num_timesteps >= 4096
